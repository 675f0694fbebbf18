"""Model validation (Section II.3 of Liu et al. 2005): fit metrics, the correlation tests of Eq.
13, Welch PSD.

Fit metrics, for measured y and prediction yhat over the same samples:
NMSE = sum (y - yhat)^2 / sum (y - ybar)^2, NRMSE = sqrt(NMSE), R^2 = 1 - NMSE.

Correlation tests (Billings & Voon 1986; Eq. 13 of Liu et al. (2005)). With a prime meaning the
mean removed and phi_ab(tau) = sum_k a(k) b(k + tau) / sqrt(sum a^2 sum b^2) over the overlap:

=======  =====================================  =====================
``ee``   phi_e'e'(tau) = delta(tau)             tau = 1..L (tau=0 is 1)
``ue``   phi_u'e'(tau) = 0                      tau = -L..L
``u2e``  phi_(u^2)'e'(tau) = 0                  tau = -L..L
``u2e2`` phi_(u^2)'(e^2)'(tau) = 0              tau = -L..L
``e_eu`` phi_e'(e u)'(tau): e(k) vs e(k-1-tau)u(k-1-tau) = 0,  tau = 0..L
=======  =====================================  =====================

The 95% band is +-1.96/sqrt(N). Pass/fail of one test (documented rule): under the null
hypothesis (white residuals independent of the input) each value is ~N(0, 1/N), so about
5% of the lags fall outside the band by chance. A test passes when BOTH

* the number of lags outside the band is at most its 99.5% quantile under the null, and
* the largest |phi| is at most z/sqrt(N) with z the two-sided Bonferroni 0.5% point for
  n_lags values (3.49 for 41 lags, 3.29 for 20),

so a correct model fails a test with probability about 1% and one of the five with about
5%, while a wrong model (many lags outside, or one far outside) fails. Exactly, for white
residuals and a white input (independent lags, independent tests under the null), a test of
n lags with at most k outside and the largest at most z passes with probability
sum_{j<=k} C(n, j) q1^j q0^(n-j), q0 = P(|Z| <= 1.96), q1 = P(1.96 < |Z| <= z); with
max_lag = 20 the five tests reject a correct model in 4.1% of the windows
(:func:`window_false_rejection_rate`).

The count quantile: for ``ee`` and ``e_eu`` the null values at different lags are
independent, so it is the Binomial(n_lags, 0.05) quantile (6 of 41, 4 of 20). For ``ue``,
``u2e`` and ``u2e2`` the values at lags tau_i, tau_j are correlated like the input series
itself (Cov = rho_a(tau_i - tau_j)/N for a = u', (u^2)'), so a narrow-band input makes
exceedances come in runs: the quantile is then taken from 4000 seeded draws of N(0, R_a)
with R_a the input's sample autocorrelation (Toeplitz). An input whose autocorrelation is
within 3.5/sqrt(N) of zero at every lag 1..2L counts as white and gets the binomial
quantile directly (the draws would reproduce it). With a single tone the count rule
therefore allows long runs and the Bonferroni max rule does the work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

from ..errors import DataError
from ..recording.spectra import welch

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

TEST_NAMES = ("ee", "ue", "u2e", "u2e2", "e_eu")
ALPHA_COUNT = 0.005
ALPHA_MAX = 0.005
N_DRAWS = 4000
WHITE_ACF = 3.5  # |rho(tau)| * sqrt(N) below this at every tau: the input counts as white


@dataclass(frozen=True)
class FitMetrics:
    """NMSE, NRMSE and R^2 of a prediction (inf/-inf if the prediction is not finite)."""

    nmse: float
    nrmse: float
    r2: float

    def to_dict(self) -> dict[str, float]:
        return {"nmse": self.nmse, "nrmse": self.nrmse, "r2": self.r2}


def fit_metrics(y: FloatArray, yhat: FloatArray) -> FitMetrics:
    """Fit of ``yhat`` to ``y`` (same length); a non-finite ``yhat`` scores NMSE = inf."""
    y = np.asarray(y, dtype=np.float64)
    yhat = np.asarray(yhat, dtype=np.float64)
    if y.shape != yhat.shape or y.ndim != 1 or len(y) < 2:
        raise DataError(
            f"fit metrics need two 1-D series of equal length >= 2 ({y.shape}, {yhat.shape})")
    if not np.all(np.isfinite(y)):
        raise DataError("fit metrics: the measured series has non-finite samples")
    sst = float(np.sum((y - y.mean()) ** 2))
    if not sst > 0:
        raise DataError("fit metrics: the measured series is constant (no variance to explain)")
    if not np.all(np.isfinite(yhat)):
        return FitMetrics(nmse=float("inf"), nrmse=float("inf"), r2=float("-inf"))
    nmse = float(np.sum((y - yhat) ** 2)) / sst
    return FitMetrics(nmse=nmse, nrmse=float(np.sqrt(nmse)), r2=1.0 - nmse)


@dataclass(frozen=True)
class CorrelationTest:
    """One correlation test: normalised correlation per lag, band and verdict."""

    name: str
    lags: IntArray
    values: FloatArray
    band: float  # 1.96 / sqrt(N)
    max_abs: float
    passed: bool
    n_outside: int = 0
    max_outside: int = 0  # allowed number of lags outside the band
    max_allowed: float = 0.0  # allowed largest |phi|

    def to_dict(self) -> dict[str, Any]:
        return {"max_abs": self.max_abs, "band": self.band, "pass": self.passed,
                "n_outside": self.n_outside, "n_lags": len(self.lags),
                "n_allowed": self.max_outside, "max_allowed": self.max_allowed}


@dataclass(frozen=True)
class CorrelationTests:
    """The five tests of Eq. 13 of Liu et al. (2005)."""

    ee: CorrelationTest
    ue: CorrelationTest
    u2e: CorrelationTest
    u2e2: CorrelationTest
    e_eu: CorrelationTest

    @property
    def all_pass(self) -> bool:
        return all(t.passed for t in self.tests())

    def tests(self) -> tuple[CorrelationTest, ...]:
        return (self.ee, self.ue, self.u2e, self.u2e2, self.e_eu)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Shape: {"ee": {"max_abs", "band", "pass", ...}, "ue": ..., ...}."""
        return {t.name: t.to_dict() for t in self.tests()}


def xcorr(a: FloatArray, b: FloatArray, lags: IntArray) -> FloatArray:
    """phi_ab(tau) = sum_k a(k) b(k+tau) / sqrt(sum a^2 sum b^2) for each tau (any sign)."""
    n = len(a)
    norm = float(np.linalg.norm(a) * np.linalg.norm(b))  # not sqrt(a.a * b.b): overflows
    out = np.zeros(len(lags))
    if not norm > 0:
        return out
    for i, tau in enumerate(np.asarray(lags).tolist()):
        if tau >= 0:
            out[i] = np.dot(a[: n - tau], b[tau:])
        else:
            out[i] = np.dot(a[-tau:], b[: n + tau])
    return out / norm


def _count_limit(n_lags: int, acf: FloatArray | None, lags: IntArray) -> int:
    """99.5% quantile of the number of |phi| > 1.96/sqrt(N) under the null."""
    if acf is None:
        return _binomial_limit(n_lags)
    diff = np.abs(lags[:, None] - lags[None, :])
    cov = acf[diff]
    w, v = np.linalg.eigh(cov)
    keep = w > 1e-12 * max(float(w.max()), 1e-300)  # narrow-band: only a few directions
    root = v[:, keep] * np.sqrt(w[keep])
    z = _draws(n_lags)[:, : int(keep.sum())] @ root.T
    counts = np.count_nonzero(np.abs(z) > 1.96, axis=1)
    return int(np.quantile(counts, 1.0 - ALPHA_COUNT, method="higher"))


@lru_cache(maxsize=64)
def _binomial_limit(n_lags: int) -> int:
    """The (1 - ALPHA_COUNT) quantile of Binomial(n_lags, 0.05): the smallest count whose
    distribution function reaches it (scipy.special: scipy.stats would cost the live nodes
    half a second of imports)."""
    q = 1.0 - ALPHA_COUNT
    return next((k for k in range(n_lags + 1) if special.bdtr(k, n_lags, 0.05) >= q), n_lags)


@lru_cache(maxsize=64)
def _max_limit(n_lags: int) -> float:
    """Two-sided Bonferroni point for n_lags values at level ALPHA_MAX."""
    return float(special.ndtri(1.0 - ALPHA_MAX / (2.0 * n_lags)))  # the normal quantile


def false_rejection_rate(n_lags: int) -> float:
    """Probability that one test of ``n_lags`` independent null values fails (module doc)."""
    k = _binomial_limit(n_lags)
    q_far = 2.0 * float(special.ndtr(-_max_limit(n_lags)))  # beyond the largest allowed
    q_in = 1.0 - 2.0 * float(special.ndtr(-1.96))  # inside the band
    q_out = 1.0 - q_in - q_far  # outside the band, not beyond the largest allowed
    p_pass = sum(math.comb(n_lags, j) * q_out**j * q_in ** (n_lags - j) for j in range(k + 1))
    return 1.0 - p_pass


@lru_cache(maxsize=8)
def window_false_rejection_rate(max_lag: int = 20) -> float:
    """Share of windows in which the five tests reject a correct model (white residuals and
    input): 1 - prod over the tests of their pass probabilities; 0.0414 for max_lag 20."""
    lags = (max_lag, 2 * max_lag + 1, 2 * max_lag + 1, 2 * max_lag + 1, max_lag + 1)
    p_pass = 1.0
    for n in lags:
        p_pass *= 1.0 - false_rejection_rate(n)
    return 1.0 - p_pass


@lru_cache(maxsize=8)
def _draws(n_lags: int) -> FloatArray:
    """Fixed standard normal draws (seeded: the verdict is deterministic)."""
    z = np.random.default_rng(20240613).standard_normal((N_DRAWS, n_lags))
    z.setflags(write=False)
    return z


def _acf(a: FloatArray, max_shift: int) -> FloatArray | None:
    """Biased sample autocorrelation rho_a(0..max_shift) (positive semi-definite), or None
    when the series is white within sampling error (|rho(tau)| <= 3.5/sqrt(N), tau >= 1):
    then the binomial count quantile applies and no draws are needed."""
    acf = xcorr(a, a, np.arange(max_shift + 1, dtype=np.intp))
    if float(np.max(np.abs(acf[1:]), initial=0.0)) <= WHITE_ACF / np.sqrt(len(a)):
        return None
    return acf


@lru_cache(maxsize=16)
def _input_limits(uc: bytes, u2: bytes, max_lag: int) -> tuple[int, int]:
    """The count limits of ``ue`` and of ``u2e``/``u2e2`` (two-sided lags) for the input u'
    and (u^2)' given as float64 bytes. They depend on the input alone, and the tests of
    the speed and the position model of one window share it: computed once per input."""
    two_sided = np.arange(-max_lag, max_lag + 1, dtype=np.intp)
    limits = (_count_limit(len(two_sided), _acf(np.frombuffer(a), 2 * max_lag), two_sided)
              for a in (uc, u2))
    return next(limits), next(limits)


def _judge(name: str, lags: IntArray, values: FloatArray, n: int,
           k_max: int | None = None) -> CorrelationTest:
    """The verdict of one test; ``k_max`` the count limit when the null values at
    different lags are correlated, else the binomial limit for ``lags``."""
    band = 1.96 / float(np.sqrt(n))
    k_max = _binomial_limit(len(lags)) if k_max is None else k_max
    v_max = _max_limit(len(lags)) / float(np.sqrt(n))
    max_abs = float(np.max(np.abs(values))) if len(values) else 0.0
    n_out = int(np.count_nonzero(np.abs(values) > band))
    return CorrelationTest(
        name=name, lags=lags, values=values, band=band, max_abs=max_abs,
        passed=bool(n_out <= k_max and max_abs <= v_max), n_outside=n_out,
        max_outside=k_max, max_allowed=v_max,
    )


def correlation_tests(residuals: FloatArray, u: FloatArray, max_lag: int = 20) -> CorrelationTests:
    """The five Billings-Voon tests of Eq. 13 of Liu et al. (2005) on residuals e(k) and input u(k).

    ``residuals`` and ``u`` are aligned sample by sample (u(k) is the input stamped at k).
    """
    e = np.asarray(residuals, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    n = len(e)
    if u.shape != e.shape or e.ndim != 1:
        raise DataError(f"residuals and input must be 1-D of equal length ({e.shape}, {u.shape})")
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(u))):
        raise DataError("correlation tests: residuals or input have non-finite samples")
    if max_lag < 1 or n < 4 * max_lag:
        raise DataError(
            f"correlation tests need max_lag >= 1 and >= {4 * max_lag} samples (got {n})")
    ec = e - e.mean()
    uc = u - u.mean()
    u2 = u * u - np.mean(u * u)
    e2 = e * e - np.mean(e * e)
    eu = e * u - np.mean(e * u)
    two_sided = np.arange(-max_lag, max_lag + 1, dtype=np.intp)
    pos = np.arange(1, max_lag + 1, dtype=np.intp)
    nonneg = np.arange(0, max_lag + 1, dtype=np.intp)
    k_u, k_u2 = _input_limits(uc.tobytes(), u2.tobytes(), max_lag)
    return CorrelationTests(
        ee=_judge("ee", pos, xcorr(ec, ec, pos), n),
        ue=_judge("ue", two_sided, xcorr(uc, ec, two_sided), n, k_u),
        u2e=_judge("u2e", two_sided, xcorr(u2, ec, two_sided), n, k_u2),
        u2e2=_judge("u2e2", two_sided, xcorr(u2, e2, two_sided), n, k_u2),
        # e(k) against e(k-1-tau)u(k-1-tau): a = (eu)', b = e' at lag 1 + tau
        e_eu=_judge("e_eu", nonneg, xcorr(eu, ec, nonneg + 1), n),
    )


def welch_psd(
    x: FloatArray, fs: float, nperseg: int | None = None
) -> tuple[FloatArray, FloatArray]:
    """One-sided Welch PSD (Hann, 50% overlap, mean removed); nperseg defaults to min(N, 256)."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1 or len(x) < 8:
        raise DataError(f"Welch PSD needs a 1-D series of at least 8 samples (got {x.shape})")
    if not np.all(np.isfinite(x)):
        raise DataError("Welch PSD: the series has non-finite samples")
    if not fs > 0:
        raise DataError(f"Welch PSD: sample rate must be positive (got {fs})")
    seg = min(len(x), 256) if nperseg is None else int(nperseg)
    if not 8 <= seg <= len(x):
        raise DataError(f"Welch PSD: nperseg must be in 8..{len(x)} (got {seg})")
    return welch(x, fs, nperseg=seg)
