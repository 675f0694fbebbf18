"""One-step-ahead (Eq. 10), model predicted output (Eq. 12) and k-step-ahead predictions
against scipy's lfilter and a plain simulation loop."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from narx_systems import QUADRATIC, simulate, white_input
from scipy import signal

from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.terms.model import NarxModel
from pmsm_sysid.core.validation.prediction import free_run, k_step_ahead, one_step_ahead
from pmsm_sysid.core.validation.prediction import simulate as run

LINEAR3 = {"y(k-1)": 1.2, "y(k-2)": -0.5, "u(k-1)": 0.7, "u(k-3)": 0.2}


def test_free_run_of_a_linear_model_equals_lfilter() -> None:
    u = white_input(500)
    model = NarxModel.from_terms(LINEAR3)
    # zero initial conditions: y = B(z)/A(z) u with B = 0.7 z^-1 + 0.2 z^-3
    expected = signal.lfilter([0.0, 0.7, 0.0, 0.2], [1.0, -1.2, 0.5], u)
    lag = model.max_lag
    out = free_run(model, u, expected[:lag])
    np.testing.assert_allclose(out[lag:], expected[lag:], rtol=1e-12, atol=1e-12)
    assert np.array_equal(out[:lag], expected[:lag])


def test_free_run_of_a_nonlinear_model_equals_the_simulation() -> None:
    u = white_input(400, seed=2)
    y = simulate(QUADRATIC, u)  # noise-free
    model = NarxModel.from_terms(QUADRATIC)
    np.testing.assert_allclose(free_run(model, u, y[:2]), y, rtol=1e-12, atol=1e-12)


def test_one_step_ahead_resets_on_measured_outputs() -> None:
    u = white_input(300, seed=4)
    y = simulate(QUADRATIC, u, noise_std=0.1, seed=4)
    model = NarxModel.from_terms(QUADRATIC)
    osa = one_step_ahead(model, y, u)
    assert np.all(np.isnan(osa[:2]))
    # the residual of the true model is exactly the equation noise
    e = 0.1 * np.random.default_rng(4).standard_normal(300)
    np.testing.assert_allclose(y[2:] - osa[2:], e[2:], atol=1e-12)


def test_k_step_ahead() -> None:
    u = white_input(200, seed=5)
    y = simulate(QUADRATIC, u, noise_std=0.05, seed=5)
    model = NarxModel.from_terms(QUADRATIC)
    np.testing.assert_array_equal(k_step_ahead(model, y, u, 1), one_step_ahead(model, y, u))
    k = 4
    ks = k_step_ahead(model, y, u, k)
    assert np.all(np.isnan(ks[: 2 + k - 1])) and np.all(np.isfinite(ks[2 + k - 1:]))
    for t in (5, 17, 100, 199):
        # independent: free run started from the measured outputs up to t-k
        start = t - k - 1  # y[start], y[start+1] measured = the 2 lags of y(t-k+1)
        seg = free_run(model, u[start: t + 1], y[start: start + 2])
        assert ks[t] == pytest.approx(seg[-1], rel=1e-12)
    # a horizon longer than the record is a free run from the first L samples
    long = k_step_ahead(model, y, u, 500)
    assert np.all(np.isnan(long))


def test_divergence_is_flagged_without_overflow_warnings() -> None:
    u = white_input(2000)
    model = NarxModel.from_terms({"y(k-1)": 1.5, "u(k-1)": 1.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = run(model, u, np.zeros(1))
    assert res.diverged and res.diverged_at is not None
    assert np.all(np.isfinite(res.y[: res.diverged_at]))
    assert np.all(np.isnan(res.y[res.diverged_at:]))
    assert np.max(np.abs(res.y[: res.diverged_at])) <= 1e6
    stable = run(NarxModel.from_terms(LINEAR3), u, np.zeros(3))
    assert not stable.diverged and stable.diverged_at is None


def test_bad_inputs_raise_data_errors() -> None:
    model = NarxModel.from_terms(LINEAR3)
    u = white_input(50)
    bad = u.copy()
    bad[7] = np.nan
    with pytest.raises(DataError, match="non-finite"):
        one_step_ahead(model, u, bad)
    with pytest.raises(DataError, match="equal length"):
        one_step_ahead(model, u[:10], u)
    with pytest.raises(DataError, match="initial outputs"):
        free_run(model, u, np.zeros(2))
    with pytest.raises(DataError, match="k >= 1"):
        k_step_ahead(model, u, u, 0)


def _plain_free_run(model: NarxModel, u: np.ndarray, y_init: np.ndarray,
                    bound: float) -> tuple[list[float], int | None]:
    """Eq. 12 as the plain loop over samples, terms and factors (the reference)."""
    lag = model.max_lag
    y = [*map(float, y_init[:lag]), *([0.0] * (len(u) - lag))]
    terms = [(float(th), t.y_lags, t.u_lags) for t, th in zip(model.terms, model.estimates,
                                                              strict=True)]
    for k in range(lag, len(u)):
        acc = 0.0
        for theta, ylags, ulags in terms:
            v = theta
            for i in ylags:
                v *= y[k - i]
            for j in ulags:
                v *= float(u[k - j])
            acc += v
        if not abs(acc) <= bound:
            return y[:k], k
        y[k] = acc
    return y, None


def _random_model(rng: np.random.Generator) -> NarxModel:
    """Up to 8 distinct terms in random order: a constant, pure input, pure output and mixed
    terms of degree 1 or 2, lags 1-12."""
    factors = [*(f"y(k-{i})" for i in range(1, 13)), *(f"u(k-{j})" for j in range(1, 13))]
    names = {"const"}
    while len(names) < 8:
        names.add("".join(sorted(rng.choice(factors, size=rng.integers(1, 3)))))
    order = rng.permutation(sorted(names))
    return NarxModel.from_dict({
        "terms": [{"name": str(n), "estimate": float(rng.normal(scale=0.3))} for n in order],
        "structure": {"ny": 12, "nu": 12, "degree": 2, "delay": 1}})


@pytest.mark.parametrize("seed", range(6))
def test_the_unrolled_free_run_is_the_plain_loop_bit_for_bit(seed: int) -> None:
    """Random structures on inputs that keep them bounded and on ones that make them
    diverge (a small bound): the same floats and the same divergence index."""
    rng = np.random.default_rng(seed)
    diverged = bounded = 0
    for _ in range(8):
        model = _random_model(rng)
        u = rng.normal(size=400)
        y0 = rng.normal(scale=0.1, size=model.max_lag)
        for bound in (1e6, 0.5):
            ref, at = _plain_free_run(model, u, y0, bound)
            got = run(model, u, y0, limit=bound)
            assert got.diverged_at == at and got.diverged == (at is not None)
            assert got.y[: len(ref)].tolist() == ref  # the same floats, not close ones
            assert np.isnan(got.y[len(ref):]).all()
            diverged += at is not None
            bounded += at is None
    assert diverged >= 4 and bounded >= 4  # both paths are exercised
