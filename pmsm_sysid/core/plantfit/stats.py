"""Inference under coloured residuals: AR prewhitening, nested F-tests, held-out comparison.

The equation-error residual is low-pass filtered and the left-out physics is coloured, so
ordinary least-squares p-values would be far too optimistic. Every test here first fits an
AR(p) model to the residual under the null hypothesis (order by BIC, Yule-Walker) and
filters the data with it (feasible generalised least squares, Cochrane-Orcutt): the whitened
residual is close to white and the classical F distribution applies.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import special
from scipy.linalg import solve_toeplitz
from scipy.linalg._solve_toeplitz import levinson
from scipy.signal import lfilter

from ..validation.correlation import fit_metrics
from .memo import ContentCache, content_key

FloatArray = NDArray[np.float64]

MAX_AR_ORDER = 20
#: Whitening filters of the latest residuals (by content).
WHITENERS = ContentCache(1 << 20)


def f_logsf(x: float, dfn: float, dfd: float) -> float:
    """Natural log of the F distribution's survival function at ``x`` (``dfn``, ``dfd``
    degrees of freedom): what ``scipy.stats.f.logsf(x, dfn, dfd)`` gives, bit for bit, from
    the special functions it evaluates -- ``log(fdtrc)`` above the median, ``log1p(-fdtr)``
    at or below it; 0 at or below 0, -inf at +inf, nan for nan or degrees of freedom that
    are not positive. Hand-written for speed: measured 2.7 µs a call against 38 µs through
    the distribution object, whose argument handling was nearly all of it (a fleet row
    makes about 80 of them; test_plantfit_fdist checks it against SciPy)."""
    x, dfn, dfd = float(x), float(dfn), float(dfd)
    if math.isnan(x) or not (dfn > 0 and dfd > 0):
        return math.nan
    if x <= 0.0:
        return 0.0
    if x == math.inf:
        return -math.inf
    with np.errstate(divide="ignore"):
        if x > special.fdtri(dfn, dfd, 0.5):
            return float(np.log(special.fdtrc(dfn, dfd, x)))
        return float(np.log1p(-special.fdtr(dfn, dfd, x)))


def ar_whitener(e: FloatArray, max_order: int = MAX_AR_ORDER) -> FloatArray:
    """Polynomial [1, -a1, ..., -ap] whitening ``e`` (Yule-Walker, order by BIC).

    The tests of one fit whiten the same residual again and again: the filters are kept
    by content (:data:`WHITENERS`)."""
    arr = np.asarray(e, dtype=np.float64)
    key = content_key("ar_whitener", arr, int(max_order))
    return WHITENERS.array(key, lambda: _ar_whitener(arr, max_order))


def _ar_whitener(e: FloatArray, max_order: int) -> FloatArray:
    """The order with the lowest BIC among those before the first unstable one (a root at
    0.999 or more, or a Yule-Walker system that cannot be solved).

    The root test (an eigenvalue problem per order) is the costly part; it is run in order,
    and only while some higher order could still lower the BIC: once none can
    (:func:`_settled`), the stability of the orders above cannot change the choice. The
    result is that of testing every order (test_plantfit_speed checks it)."""
    x = e - float(np.mean(e))
    n = len(x)
    max_order = max(0, min(max_order, n // 10))
    r = np.array([float(x[: n - j] @ x[j:]) for j in range(max_order + 1)]) / n
    if r[0] <= 0:
        return np.ones(1)
    best = (math.log(r[0]), np.ones(1))
    fits = _fits(r, n, max_order)
    lowest = list(itertools.accumulate((bic for bic, _ in reversed(fits)), min))[::-1]
    for (bic, poly), below in zip(fits, lowest, strict=True):
        if _settled(below, best[0]) or _max_root(poly) >= 0.999:
            break
        if bic < best[0]:
            best = (bic, poly)
    return best[1]


def _fits(r: FloatArray, n: int, max_order: int) -> list[tuple[float, FloatArray]]:
    """(BIC, polynomial) of the Yule-Walker fits of orders 1, 2, ... up to the first that
    cannot be solved or leaves no error variance."""
    out: list[tuple[float, FloatArray]] = []
    direct = bool(np.all(np.isfinite(r)))  # else solve_toeplitz says what is wrong
    for p in range(1, max_order + 1):
        try:
            a = _yule_walker(r, p) if direct else solve_toeplitz(r[:p], r[1:p + 1])
        except np.linalg.LinAlgError:
            break
        sigma2 = r[0] - float(np.dot(a, r[1:p + 1]))
        if sigma2 <= 0:
            break
        poly = np.concatenate([[1.0], -a])
        bic = math.log(sigma2) + p * math.log(n) / n
        # a non-finite fit is root-tested when reached (the test refuses it, as it did)
        out.append((bic if np.all(np.isfinite(poly)) else -math.inf, poly))
    return out


def _settled(lowest_ahead: float, best: float) -> bool:
    """No order from here on has a BIC below the best so far (ties keep the lower order)."""
    return not lowest_ahead < best


def _yule_walker(r: FloatArray, p: int) -> FloatArray:
    """``solve_toeplitz(r[:p], r[1:p + 1])`` for finite ``r``, by the Levinson recursion
    that function runs, without its argument checks: the same numbers, bit for bit
    (test_plantfit_speed checks it); measured: the checks were 70 % of its time, called
    20 times for each residual whitened."""
    vals = np.concatenate((r[p - 1:0:-1], r[:p]))
    return np.asarray(levinson(vals, np.ascontiguousarray(r[1:p + 1]))[0])


def _max_root(poly: FloatArray) -> float:
    """``max(abs(np.roots(poly)))`` for a monic ``poly``: the eigenvalues of the same
    companion matrix ``np.roots`` builds (measured: half of its time went to stripping
    zeros and joining arrays); a zero last coefficient goes through ``np.roots``."""
    if poly[-1] == 0.0 or len(poly) < 2:
        return float(np.max(np.abs(np.roots(poly)))) if len(poly) > 1 else 0.0
    n = len(poly)
    A = np.diag(np.ones((n - 2,), poly.dtype), -1)
    A[0, :] = -poly[1:] / poly[0]
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def whiten(poly: FloatArray, arr: FloatArray) -> FloatArray:
    """Apply the whitening filter along axis 0, dropping its start-up samples."""
    p = len(poly) - 1
    a = np.asarray(arr, dtype=np.float64)
    if a.size == 0:
        return np.zeros((max(0, a.shape[0] - p), *a.shape[1:]))
    b = np.asarray(poly, dtype=np.float64)
    if a.ndim > 2 or b.ndim != 1:
        out: FloatArray = lfilter(poly, [1.0], a, axis=0)[p:]
        return out
    # lfilter(poly, [1.0], a, axis=0) convolves each column with the polynomial (its FIR
    # path) into the rows of one buffer, seen transposed; the same here, bit for bit and
    # with its strides, without its generic axis handling. Hand-written for speed
    # (measured: 8.8 us for a 683 x 3 array, 20.7 us through lfilter; 2.2 us and 13.8 us
    # for one column; a fleet row whitens about 300 arrays)
    n = a.shape[0]
    if a.ndim == 1:
        one: FloatArray = np.asarray(np.convolve(b, a)[p:n], dtype=np.float64)
        return one
    full = np.empty((a.shape[1], n + p))
    for j in range(a.shape[1]):
        full[j] = np.convolve(b, a[:, j])
    return full.T[p:n]


def lstsq(X: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least squares coefficients and residual (empty X gives zeros and y)."""
    if X.shape[1] == 0:
        return np.zeros(0), y.copy()
    beta = np.asarray(np.linalg.lstsq(X, y, rcond=None)[0], dtype=np.float64)
    return beta, y - X @ beta


@dataclass(frozen=True)
class NestedTest:
    """F-test of extra columns against a base model, both whitened by the base residual."""

    f_stat: float
    dof1: int
    dof2: int
    log10_p: float
    ar_order: int

    def corrected_log10_p(self, n_tests: float) -> float:
        """log10 of the Bonferroni-corrected p-value (capped at 0)."""
        return min(0.0, self.log10_p + math.log10(max(n_tests, 1.0)))


def nested_f_test(y: FloatArray, base: FloatArray, extra: FloatArray,
                  poly: FloatArray | None = None, null_whitening: bool = False) -> NestedTest:
    """Does ``extra`` explain significantly more of ``y`` than ``base`` alone?

    The whitening filter is fitted to the residual of the larger model (as feasible GLS
    does), so that an effect present in ``y`` is not mistaken for coloured noise. A wide
    generic basis (many bins) would soak up the slow part of the noise that way and make
    the rest look whiter than the noise is; ``null_whitening`` then fits the filter to the
    residual of ``base`` alone, which is the noise itself under the null hypothesis.
    """
    if poly is None:
        cols = base if null_whitening else np.hstack([base, extra])
        _, e1 = lstsq(cols, y)
        w = ar_whitener(e1)
    else:
        w = poly
    yw, bw, xw = whiten(w, y), whiten(w, base), whiten(w, extra)
    _, r0 = lstsq(bw, yw)
    full = np.hstack([bw, xw])
    _, r1 = lstsq(full, yw)
    rank_full = np.linalg.matrix_rank(full) if full.shape[1] else 0
    rank_base = np.linalg.matrix_rank(bw) if bw.shape[1] else 0
    q = max(1, int(rank_full - rank_base))
    dof2 = max(1, len(yw) - int(rank_full))
    sse0, sse1 = float(r0 @ r0), float(r1 @ r1)
    f = max(0.0, (sse0 - sse1) / q) / max(sse1 / dof2, 1e-300)
    logp = f_logsf(f, q, dof2) / math.log(10.0)
    return NestedTest(f_stat=f, dof1=q, dof2=dof2, log10_p=logp, ar_order=len(w) - 1)


@dataclass(frozen=True)
class HeldOutTest:
    """Diebold-Mariano comparison of squared held-out errors with and without an effect."""

    reduction: float
    z: float
    p_value: float

    @property
    def confirmed(self) -> bool:
        """The effect lowers the held-out mean-square error."""
        return self.reduction > 0

    @property
    def significant(self) -> bool:
        """... and by more than chance would (one-sided 5 %)."""
        return self.confirmed and self.p_value < 0.05


def held_out_test(e_without: FloatArray, e_with: FloatArray,
                  poly: FloatArray | None = None) -> HeldOutTest:
    """One-sided test that ``e_with`` has smaller mean square than ``e_without``.

    Both error series are whitened by ``poly`` (fitted on ``e_with`` when not given), then
    d_k = e_without² - e_with² is tested for a positive mean with a Newey-West (Bartlett)
    long-run variance. ``reduction`` is the fractional drop in raw mean square error.
    """
    w = ar_whitener(e_with) if poly is None else poly
    a, b = whiten(w, e_without), whiten(w, e_with)
    d = a * a - b * b
    n = len(d)
    lags = math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0))
    dc = d - d.mean()
    lrv = float(dc @ dc) / n
    for j in range(1, lags + 1):
        lrv += 2.0 * (1.0 - j / (lags + 1)) * float(dc[j:] @ dc[:-j]) / n
    se = math.sqrt(max(lrv, 1e-300) / n)
    z = float(d.mean()) / se
    ms0, ms1 = float(np.mean(e_without ** 2)), float(np.mean(e_with ** 2))
    red = (ms0 - ms1) / ms0 if ms0 > 0 else 0.0
    return HeldOutTest(reduction=red, z=z, p_value=float(special.ndtr(-z)))  # norm.sf(z)


def nrmse(target: FloatArray, error: FloatArray) -> float:
    """||error|| / ||target - mean(target)||: the NRMSE of the prediction target - error."""
    return fit_metrics(target, np.asarray(target) - np.asarray(error)).nrmse
