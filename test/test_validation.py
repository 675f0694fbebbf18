"""Fit metrics, the correlation tests of seed Eq. 13 (statistical behaviour under the null and
under specific model errors), Welch PSD, and validate_narx end to end."""

from __future__ import annotations

import numpy as np
import pytest
from narx_systems import QUADRATIC, simulate, white_input
from scipy import signal

from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.selection.identify import FitConfig, fit_narx, validate_narx
from pmsm_sysid.core.terms.model import NarxModel, Structure
from pmsm_sysid.core.validation.correlation import (
    TEST_NAMES,
    correlation_tests,
    fit_metrics,
    welch_psd,
    xcorr,
)


def test_fit_metrics_closed_forms() -> None:
    rng = np.random.default_rng(0)
    y = rng.standard_normal(500)
    m = fit_metrics(y, np.full(500, y.mean()))
    assert (m.nmse, m.r2) == pytest.approx((1.0, 0.0))
    assert fit_metrics(y, y).nmse == 0.0
    half = fit_metrics(y, y.mean() + 0.5 * (y - y.mean()))  # error = half the deviation
    assert half.nmse == pytest.approx(0.25) and half.nrmse == pytest.approx(0.5)
    assert half.r2 == pytest.approx(0.75)
    bad = y.copy()
    bad[3] = np.nan
    assert fit_metrics(y, bad).nmse == np.inf and fit_metrics(y, bad).r2 == -np.inf
    with pytest.raises(DataError, match="constant"):
        fit_metrics(np.ones(10), np.ones(10))
    with pytest.raises(DataError, match="equal length"):
        fit_metrics(y, y[:-1])


def test_xcorr_matches_numpy_correlate() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal(300), rng.standard_normal(300)
    lags = np.arange(-7, 8)
    full = np.correlate(b, a, mode="full")  # full[n-1+tau] = sum_k a(k) b(k+tau)
    expected = full[299 + lags] / np.sqrt((a @ a) * (b @ b))
    np.testing.assert_allclose(xcorr(a, b, lags), expected, rtol=1e-12, atol=1e-15)


def test_null_hypothesis_passes_with_high_probability() -> None:
    """White residuals independent of a white input: all five pass in >= 90% of trials
    (the rule is designed for ~5% family-wise false alarms)."""
    rng = np.random.default_rng(2)
    trials, passed = 300, 0
    per_test = dict.fromkeys(TEST_NAMES, 0)
    for _ in range(trials):
        e, u = rng.standard_normal(1000), rng.uniform(-1, 1, 1000)
        ct = correlation_tests(e, u)
        passed += ct.all_pass
        for t in ct.tests():
            per_test[t.name] += t.passed
    assert passed / trials >= 0.90
    assert all(v / trials >= 0.97 for v in per_test.values()), per_test


@pytest.mark.slow
def test_null_rate_holds_for_a_single_tone_input() -> None:
    """A narrow-band input makes the lag values correlated; the count rule follows the
    input's autocorrelation, so a correct model still passes (the paper's protocol)."""
    rng = np.random.default_rng(6)
    k = np.arange(1000)
    trials = 150
    passed = sum(
        correlation_tests(rng.standard_normal(1000),
                          np.sin(2 * np.pi * 0.033 * k + rng.uniform(0, 2 * np.pi))).all_pass
        for _ in range(trials))
    assert passed / trials >= 0.90
    # and an unmodelled input term is still caught with that input
    u = np.sin(2 * np.pi * 0.033 * k)
    e = rng.standard_normal(1000)
    assert not correlation_tests(e + 0.3 * np.roll(u, 2), u).ue.passed


def _fails(residuals: np.ndarray, u: np.ndarray) -> set[str]:
    return {t.name for t in correlation_tests(residuals, u).tests() if not t.passed}


def test_each_test_catches_its_model_error() -> None:
    rng = np.random.default_rng(3)
    n = 1000
    u = rng.uniform(-1, 1, n)
    e = rng.standard_normal(n)
    lag = np.roll  # shift helper: lag(x, d)[k] = x[k-d]
    assert "ee" in _fails(e + 0.6 * lag(e, 1), u)  # unmodelled noise dynamics
    assert "ue" in _fails(e + 0.5 * lag(u, 3), u)  # missing linear input term
    u2 = u * u - np.mean(u * u)
    assert "u2e" in _fails(e + 1.5 * lag(u2, 2), u)  # missing even input nonlinearity
    # residual variance growing with u^2(k-1): heteroscedastic, missing noise x input^2 term
    assert "u2e2" in _fails(e * (0.3 + 2.0 * np.abs(lag(u, 1))), u)
    assert "e_eu" in _fails(e + 0.8 * lag(e * u, 1), u)  # missing noise x input term


def test_band_and_contract_shape() -> None:
    rng = np.random.default_rng(4)
    ct = correlation_tests(rng.standard_normal(400), rng.standard_normal(400), max_lag=10)
    d = ct.to_dict()
    assert list(d) == ["ee", "ue", "u2e", "u2e2", "e_eu"]
    for name, t in d.items():
        assert {"max_abs", "band", "pass"} <= set(t), name
        assert t["band"] == pytest.approx(1.96 / np.sqrt(400))
    assert list(ct.ee.lags) == list(range(1, 11))
    assert list(ct.ue.lags) == list(range(-10, 11))
    assert list(ct.e_eu.lags) == list(range(0, 11))
    with pytest.raises(DataError, match="samples"):
        correlation_tests(np.ones(30), np.ones(30), max_lag=10)


def test_welch_psd_peak_and_parseval() -> None:
    fs = 500.0
    k = np.arange(4096)
    noise = 0.1 * np.random.default_rng(5).standard_normal(4096)
    x = 2.0 * np.sin(2 * np.pi * 16.5 * k / fs) + noise
    f, p = welch_psd(x, fs)
    assert abs(f[np.argmax(p)] - 16.5) <= fs / 256
    assert np.sum(p) * (f[1] - f[0]) == pytest.approx(np.var(x), rel=0.05)
    _f2, p2 = signal.welch(x, fs=fs, nperseg=256)
    np.testing.assert_allclose(p, p2)
    with pytest.raises(DataError):
        welch_psd(x[:4], fs)


def test_validate_narx_correct_model_passes_wrong_model_fails() -> None:
    u = white_input(3000, seed=7)
    y = simulate(QUADRATIC, u, noise_std=0.02, seed=7)
    s = Structure(ny=2, nu=2, degree=2)
    fit = fit_narx(y[:1500], u[:1500], FitConfig(structure=s, n_terms=5))
    rep = validate_narx(fit.model, y[:1500], u[:1500], y[1500:], u[1500:])
    assert rep.correlation.all_pass
    assert rep.validation is not None and rep.validation.r2 > 0.99
    assert rep.osa_r2 > 0.99 and not rep.free_run_diverged
    d = rep.to_dict()
    assert {"nmse", "r2", "osa_r2"} <= set(d["validation"])
    # a linear model of the quadratic system misses u(k-2)^2 and y(k-1)u(k-2)
    lin = fit_narx(y[:1500], u[:1500], FitConfig(structure=Structure(ny=2, nu=2, degree=1),
                                                 n_terms=4))
    bad = validate_narx(lin.model, y[:1500], u[:1500], y[1500:], u[1500:])
    assert not bad.correlation.all_pass
    assert not bad.correlation.u2e.passed
    assert bad.validation is not None and bad.validation.r2 < rep.validation.r2


def test_validate_reports_divergence() -> None:
    u = white_input(500)
    y = simulate(QUADRATIC, u, noise_std=0.01)
    unstable = NarxModel.from_terms({"y(k-1)": 1.3, "u(k-1)": 0.8})
    rep = validate_narx(unstable, y, u, y, u)
    assert rep.free_run_diverged and rep.estimation.nmse == np.inf


def test_the_binomial_limits_are_scipy_stats_quantiles() -> None:
    """The correlation tests' count limit and Bonferroni point (computed with scipy.special)
    equal scipy.stats' binomial and normal quantiles; the window test's tail is the binomial
    survival function for windows that do not overlap, and for overlapping ones the
    binomial's continued to failed / phi of made / phi windows (scipy.stats' beta law)."""
    from scipy import stats

    from pmsm_sysid.core.validation import correlation
    from pmsm_sysid.core.validation.windows import NULL_RATE, dispersion, window_rate

    for n_lags in range(1, 201):
        assert correlation._binomial_limit(n_lags) == int(
            stats.binom.ppf(1.0 - correlation.ALPHA_COUNT, n_lags, 0.05))
        assert correlation._max_limit(n_lags) == pytest.approx(
            float(stats.norm.ppf(1.0 - correlation.ALPHA_MAX / (2.0 * n_lags))), rel=1e-14)
    for made in (1, 12, 52, 120):
        for failed in range(1, made + 1):
            want = float(stats.binom.sf(failed - 1, made, NULL_RATE))
            got = window_rate(made - failed, made, shift=1.6)["p_value"]
            assert got == pytest.approx(want, rel=1e-9, abs=1e-300)
            phi = dispersion(made)
            assert phi >= 1.0
            k, n = failed / phi, made / phi
            want = float(stats.beta.cdf(NULL_RATE, k, n - k + 1))
            assert window_rate(made - failed, made)["p_value"] == pytest.approx(
                want, rel=1e-9, abs=1e-300)


def test_the_dispersion_is_the_variance_of_overlapping_windows_failed_count(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Windows that share samples pass and fail together: simulated outcomes of m-sample
    windows at a hop of one sample (a window fails when its samples' mean is high, about 1
    in 20), their correlation by shift measured and given to :func:`dispersion` as its
    table; the variance of the failed count over many runs of n windows is then phi times
    the binomial variance, and the test's false alarms stay within its level where the
    plain binomial test's do not."""
    from scipy import stats

    from pmsm_sysid.core.validation import windows

    rng = np.random.default_rng(7)
    m, n, runs = 8, 24, 4000
    z = rng.standard_normal((runs, n + m - 1))
    means = np.lib.stride_tricks.sliding_window_view(z, m, axis=1).mean(axis=2)
    fail = means > stats.norm.ppf(1 - windows.NULL_RATE) / np.sqrt(m)  # (runs, n)
    f = fail.ravel().astype(float)
    p = fail.mean()
    rho = [1.0] + [float(np.mean((fail[:, :-k] - p) * (fail[:, k:] - p)) / (p * (1 - p)))
                   for k in range(1, m)] + [0.0]
    table = tuple((k / m, r) for k, r in enumerate(rho))
    monkeypatch.setattr(windows, "_SHIFTS", np.array([t[0] for t in table]))
    monkeypatch.setattr(windows, "_RHO", np.array([t[1] for t in table]))
    counts = fail.sum(axis=1)
    measured = counts.var() / (n * p * (1 - p))
    assert f.mean() == pytest.approx(0.05, abs=0.01)
    assert measured > 2.0  # far from independent windows
    assert windows.dispersion(n, 1.0 / m) == pytest.approx(measured, rel=0.1)
    alarms = np.mean([not windows.window_rate(n - c, n, 1.0 / m)["consistent"]
                      for c in counts])
    plain = np.mean([stats.binom.sf(c - 1, n, windows.NULL_RATE) < windows.LEVEL
                     for c in counts])
    assert alarms <= windows.LEVEL * 1.5 < 3 * windows.LEVEL < plain, (alarms, plain)


def test_the_input_limits_are_the_count_limits_of_each_input_and_shared_by_residuals() -> None:
    """The count limits of ue, u2e and u2e2 follow the input's autocorrelation only: they
    are computed once per input and reused for other residuals on the same input (the
    speed and position models of one window). Each equals the limit computed directly
    from that input's autocorrelation, and another input gets its own."""
    from pmsm_sysid.core.validation.correlation import _acf, _count_limit

    rng = np.random.default_rng(11)
    k = np.arange(1000)
    lags = np.arange(-20, 21, dtype=np.intp)
    for u in (np.sin(2 * np.pi * 0.02 * k) + 0.05 * rng.standard_normal(1000),
              np.sign(np.sin(2 * np.pi * 0.007 * k)) + 0.3 * rng.standard_normal(1000)):
        uc, u2 = u - u.mean(), u * u - np.mean(u * u)
        k_u, k_u2 = (_count_limit(41, _acf(a, 40), lags) for a in (uc, u2))
        assert k_u > 6  # coloured: more than the binomial limit of 41 white lags
        for _ in range(2):
            ct = correlation_tests(rng.standard_normal(1000), u)
            assert (ct.ue.max_outside, ct.u2e.max_outside, ct.u2e2.max_outside) \
                == (k_u, k_u2, k_u2)
            assert ct.ee.max_outside == 4 and ct.e_eu.max_outside == 4  # binomial, 20/21 lags
