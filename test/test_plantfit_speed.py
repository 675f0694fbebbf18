"""The fit's hand-written fast paths give what the library calls they replace give, bit for
bit: the AR whitener's Yule-Walker solve and root test, and the speed prior's digest."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_toeplitz
from scipy.signal import lfilter

from pmsm_sysid.core.plantfit import stats


def _autocorrelation(e: np.ndarray, lags: int = 20) -> np.ndarray:
    x = e - e.mean()
    n = len(x)
    return np.array([float(x[: n - j] @ x[j:]) for j in range(lags + 1)]) / n


def _residuals() -> list[np.ndarray]:
    """White, AR(1) near the unit circle, and low-passed AR(2) residuals of many lengths."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(60):
        e = rng.standard_normal(int(rng.integers(200, 4000)))
        if k % 3:
            e = lfilter([1.0], [1.0, -rng.uniform(0.5, 0.9995)], e)
        if k % 3 == 2:
            e = lfilter([1.0], [1.0, -1.6, 0.7], e)
        out.append(e)
    return out


def test_yule_walker_is_solve_toeplitz_bit_for_bit() -> None:
    for e in _residuals():
        r = _autocorrelation(e)
        for p in range(1, 21):
            assert np.array_equal(stats._yule_walker(r, p), solve_toeplitz(r[:p], r[1:p + 1]))


def test_a_singular_system_is_refused_as_solve_toeplitz_refuses_it() -> None:
    r = np.array([0.0, 1.0, 0.5])
    with pytest.raises(np.linalg.LinAlgError):
        solve_toeplitz(r[:2], r[1:3])
    with pytest.raises(np.linalg.LinAlgError):
        stats._yule_walker(r, 2)


def test_max_root_is_that_of_np_roots() -> None:
    for e in _residuals():
        r = _autocorrelation(e)
        for p in range(1, 21):
            poly = np.concatenate([[1.0], -solve_toeplitz(r[:p], r[1:p + 1])])
            assert stats._max_root(poly) == np.max(np.abs(np.roots(poly)))
    for poly in ([1.0, -0.5, 0.0], [1.0, 0.0], [1.0, -1.2, 0.0, 0.0], [1.0]):
        p = np.array(poly)
        want = float(np.max(np.abs(np.roots(p)))) if len(p) > 1 else 0.0
        assert stats._max_root(p) == want


def _ar_whitener_by_library(e: np.ndarray, max_order: int) -> np.ndarray:
    """The whitener as written with solve_toeplitz and np.roots."""
    import math
    x = e - float(np.mean(e))
    n = len(x)
    max_order = max(0, min(max_order, n // 10))
    r = np.array([float(x[: n - j] @ x[j:]) for j in range(max_order + 1)]) / n
    if r[0] <= 0:
        return np.ones(1)
    best = (math.log(r[0]), np.ones(1))
    for p in range(1, max_order + 1):
        try:
            a = solve_toeplitz(r[:p], r[1:p + 1])
        except np.linalg.LinAlgError:
            break
        sigma2 = r[0] - float(np.dot(a, r[1:p + 1]))
        if sigma2 <= 0:
            break
        poly = np.concatenate([[1.0], -a])
        if np.max(np.abs(np.roots(poly))) >= 0.999:
            break
        bic = math.log(sigma2) + p * math.log(n) / n
        if bic < best[0]:
            best = (bic, poly)
    return best[1]


def test_the_whitener_is_the_library_one() -> None:
    orders = set()
    for e in _residuals():
        for m in (20, 5):
            got = stats._ar_whitener(e, m)
            assert np.array_equal(got, _ar_whitener_by_library(e, m))
            orders.add(len(got) - 1)
    assert len(orders) > 3  # the cases reach several orders (and the unit-circle stop)


def test_a_non_finite_residual_is_refused_as_before() -> None:
    e = np.ones(300)
    e[7] = np.nan
    with pytest.raises(ValueError) as new:
        stats._ar_whitener(e, 20)
    with pytest.raises(ValueError) as old:
        _ar_whitener_by_library(e, 20)
    assert str(new.value) == str(old.value)
