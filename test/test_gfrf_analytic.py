"""GFRFs (core/gfrf.py, seed Eqs. 7-9) against closed forms derived by hand."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pmsm_sysid.core.errors import GfrfError
from pmsm_sysid.core.frequency.gfrf import MAX_GRID, Gfrf, to_hz, to_norm
from pmsm_sysid.core.terms.model import NarxModel

A, B, C, D, E, G = 0.6, 1.3, 0.4, -0.7, 0.25, 0.9
RNG = np.random.default_rng(12345)
F1, F2 = RNG.uniform(-0.5, 0.5, (2, 500))


def z(f: np.ndarray) -> np.ndarray:
    return np.exp(-2j * np.pi * f)


def toy(d: float = D, const: float = 0.0) -> Gfrf:
    terms = {"y(k-1)": A, "u(k-1)": B, "u(k-1)^2": C, "y(k-1)u(k-1)": d, "y(k-1)^2": E,
             "u(k-1)^3": G}
    if const:
        terms["const"] = const
    return Gfrf.from_model(NarxModel.from_terms(terms, sample_rate_hz=500.0))


def h1_true(f: np.ndarray) -> np.ndarray:
    return B * z(f) / (1 - A * z(f))


def h2_true(f1: np.ndarray, f2: np.ndarray, d: float = D) -> np.ndarray:
    z12 = z(f1 + f2)
    num = C + d * (h1_true(f1) + h1_true(f2)) / 2 + E * h1_true(f1) * h1_true(f2)
    return z12 * num / (1 - A * z12)


def test_h1_closed_form() -> None:
    np.testing.assert_allclose(toy().h(F1), h1_true(F1), rtol=0, atol=1e-10)


def test_h2_sym_closed_form_random_points() -> None:
    np.testing.assert_allclose(toy().h(F1, F2), h2_true(F1, F2), rtol=0, atol=1e-10)


def test_h3_diagonal_closed_form_d0() -> None:
    f = F1
    h3 = z(3 * f) * (G + 2 * E * h1_true(f) * h2_true(f, f, 0.0)) / (1 - A * z(3 * f))
    got = toy(d=0.0).h(f, f, f)
    np.testing.assert_allclose(got, h3, rtol=0, atol=1e-10)
    # the same with three distinct (equal-valued) arrays: no shortcut taken
    np.testing.assert_allclose(toy(d=0.0).h(f, f.copy(), f.copy()), h3, rtol=0, atol=1e-10)


def test_constant_term_does_not_enter() -> None:
    g0, g1 = toy(), toy(const=3.7)
    for n in (1, 2, 3):
        args = [RNG.uniform(-0.5, 0.5, 50) for _ in range(n)]
        np.testing.assert_array_equal(g0.h(*args), g1.h(*args))


def test_fir_quadratic_with_distinct_lags() -> None:
    """y(k) = c u(k-1)u(k-3): H2_sym = c (z1 z2^3 + z1^3 z2) / 2, no denominator."""
    g = Gfrf.from_model(NarxModel.from_terms({"u(k-1)u(k-3)": 0.8}))
    want = 0.8 * (z(F1) * z(F2) ** 3 + z(F1) ** 3 * z(F2)) / 2
    np.testing.assert_allclose(g.h(F1, F2), want, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(g.h(F1), 0)


def test_output_lag_two_and_input_product() -> None:
    """y(k) = a y(k-2) + b u(k-2) + c u(k-1)u(k-2) + e y(k-2)^2 (lags > 1, by hand)."""
    a, b, c, e = -0.5, 2.0, 0.3, 0.2
    g = Gfrf.from_model(NarxModel.from_terms(
        {"y(k-2)": a, "u(k-2)": b, "u(k-1)u(k-2)": c, "y(k-2)^2": e}))
    h1 = lambda f: b * z(f) ** 2 / (1 - a * z(f) ** 2)  # noqa: E731
    z12 = z(F1 + F2)
    want = (c * (z(F1) * z(F2) ** 2 + z(F1) ** 2 * z(F2)) / 2
            + e * h1(F1) * h1(F2) * z12 ** 2) / (1 - a * z12 ** 2)
    np.testing.assert_allclose(g.h(F1), h1(F1), atol=1e-12)
    np.testing.assert_allclose(g.h(F1, F2), want, atol=1e-12)


def test_cross_term_three_factors() -> None:
    """y(k) = a y(k-1) + b u(k-1) + c y(k-2)u(k-1)u(k-3): H3 from the c_{1,2} term alone.

    By Eq. 7: H3_asym = c z2^1 z3^3 H1(f1) z1^2 / L3, so H3_sym averages the 6 orderings.
    """
    a, b, c = 0.5, 1.0, 0.7
    g = Gfrf.from_model(NarxModel.from_terms({"y(k-1)": a, "u(k-1)": b, "y(k-2)u(k-1)u(k-3)": c}))
    f = RNG.uniform(-0.5, 0.5, (3, 200))
    h1 = lambda x: b * z(x) / (1 - a * z(x))  # noqa: E731
    den = 1 - a * z(f.sum(axis=0))
    want = sum(c * h1(f[i]) * z(f[i]) ** 2 * z(f[j]) * z(f[k]) ** 3
               for i, j, k in itertools.permutations(range(3))) / 6 / den
    np.testing.assert_allclose(g.h(*f), want, atol=1e-12)
    np.testing.assert_array_equal(g.h(f[0], f[1]), 0)  # no quadratic term -> H2 = 0


def test_symmetry_conjugacy_and_periodicity() -> None:
    g = toy()
    f = RNG.uniform(-0.5, 0.5, (3, 100))
    h = g.h(*f)
    np.testing.assert_allclose(g.h(f[2], f[0], f[1]), h, atol=1e-12)
    np.testing.assert_allclose(g.h(-f[0], -f[1], -f[2]), np.conj(h), atol=1e-12)
    np.testing.assert_allclose(g.h_wrapped(f[0] + 1, f[1] - 2, f[2]), h, atol=1e-9)
    # Eq. 9: H_sym is the mean of H_asym over the n! orderings
    asym = [g.h(*(f[list(p)]), symmetric=False) for p in itertools.permutations(range(3))]
    np.testing.assert_allclose(sum(asym) / math.factorial(3), h, atol=1e-12)
    assert not np.allclose(asym[0], h)


def test_grids_equal_point_evaluation() -> None:
    g = toy()
    f, h2 = g.h2_grid(33)
    i, j = 5, 29
    assert h2.shape == (33, 33)
    assert h2[i, j] == pytest.approx(complex(g.h(f[i], f[j])), abs=1e-14)
    f3, h3 = g.h3_slice(17)
    assert h3[3, 11] == pytest.approx(complex(g.h(f3[3], f3[11], f3[3])), abs=1e-14)
    fc, h1 = g.h1_curve(65)
    assert fc[0] == 0.0 and fc[-1] == 0.5
    np.testing.assert_allclose(h1, h1_true(fc), atol=1e-12)


def test_linear_model_has_zero_higher_orders() -> None:
    g = Gfrf.from_model(NarxModel.from_terms({"y(k-1)": 0.9, "u(k-1)": 0.1}))
    assert g.is_linear
    np.testing.assert_array_equal(g.h(F1, F2), 0)
    np.testing.assert_array_equal(g.h(F1, F2, F1), 0)


def test_poles_of_resonant_ar2() -> None:
    r, th = 0.95, 2 * np.pi * 0.03
    g = Gfrf.from_model(NarxModel.from_terms(
        {"y(k-1)": 2 * r * np.cos(th), "y(k-2)": -r * r, "u(k-1)": 1.0, "u(k-1)^2": 0.1}))
    p = g.poles()
    assert len(p) == 2 and g.stable
    np.testing.assert_allclose(np.abs(p), r, rtol=1e-12)
    np.testing.assert_allclose(sorted(np.angle(p)), [-th, th], rtol=1e-12)
    unstable = Gfrf.from_model(NarxModel.from_terms({"y(k-1)": 1.01, "u(k-1)": 1.0}))
    assert not unstable.stable and abs(unstable.poles()[0]) == pytest.approx(1.01)


def test_hz_helpers() -> None:
    assert float(to_hz(0.033, 500.0)) == pytest.approx(16.5)
    assert float(to_norm(11.5, 500.0)) == pytest.approx(0.023)


@pytest.mark.parametrize("bad", [0.51, -0.6, float("nan"), float("inf")])
def test_bad_frequencies_raise(bad: float) -> None:
    with pytest.raises(GfrfError):
        toy().h(0.1, bad)


def test_bad_orders_and_grids() -> None:
    g = toy()
    with pytest.raises(GfrfError):
        g.h()
    with pytest.raises(GfrfError):
        g.h(0.1, 0.1, 0.1, 0.1, 0.1)
    with pytest.raises(GfrfError):
        g.h2_grid(MAX_GRID + 1)
    with pytest.raises(GfrfError):
        g.h(np.zeros(3), np.zeros(4))
    assert g.h(0.1, 0.2, 0.3, 0.05).shape == ()  # H4 is available
