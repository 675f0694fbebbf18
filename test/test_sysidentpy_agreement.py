"""Agreement with the peer library SysIdentPy 0.9 (FROLS, LeastSquares) on identical data.

SysIdentPy's regressor codes: 0 = nothing, 1000 + i = y(k-i), 2000 + j = u(k-j) (x lags start
at 1, i.e. delay d = 1). Its FROLS uses the raw output (ERR denominator sum y^2) and treats
the constant as an ordinary candidate: our ``remove_dc=False`` convention.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from narx_systems import CUBIC, QUADRATIC, coloured_input, simulate, white_input

from pmsm_sysid.core.selection.identify import FitConfig, fit_narx
from pmsm_sysid.core.terms.model import Structure, Term

sip = pytest.importorskip("sysidentpy", reason="peer library (bench extra) not installed")
from sysidentpy.basis_function import Polynomial  # noqa: E402
from sysidentpy.model_structure_selection import FROLS  # noqa: E402
from sysidentpy.parameter_estimation import LeastSquares  # noqa: E402


def _name(code_row: np.ndarray) -> str:
    factors = tuple(("y" if c < 2000 else "u", int(c) % 1000) for c in code_row if c)
    return Term(factors).name


def _peer(y: np.ndarray, u: np.ndarray, ny: int, nu: int, degree: int, n_terms: int):
    m = FROLS(order_selection=False, n_terms=n_terms, ylag=ny, xlag=nu,
              estimator=LeastSquares(), basis_function=Polynomial(degree=degree))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m.fit(X=u[:, None], y=y[:, None])
    names = [_name(row) for row in m.final_model]
    return names, m.theta.ravel(), np.asarray(m.err[:n_terms])


CASES = {
    "quadratic-coloured": (QUADRATIC, "coloured", 2, 2, 2, 5, 0.0),
    "quadratic-offset": (QUADRATIC, "white", 3, 3, 2, 8, 1.5),
    "cubic": (CUBIC, "white", 2, 2, 3, 6, 0.0),
    "wide-lags": (QUADRATIC, "coloured", 8, 6, 2, 12, -0.7),
}


@pytest.mark.parametrize("case", list(CASES))
def test_same_terms_same_order_same_coefficients(case: str) -> None:
    coeffs, kind, ny, nu, degree, n_terms, offset = CASES[case]
    u = white_input(1000) if kind == "white" else 0.5 * coloured_input(1000)
    y = simulate(coeffs, u, noise_std=0.02) + offset
    names, theta, err = _peer(y, u, ny, nu, degree, n_terms)
    s = Structure(ny=ny, nu=nu, degree=degree, delay=1, constant=True)
    f = fit_narx(y, u, FitConfig(structure=s, n_terms=n_terms, method="ofr", remove_dc=False))
    assert f.model.term_names == names
    np.testing.assert_allclose(f.model.estimates, theta, rtol=1e-6, atol=1e-12)
    # same ERR convention in this mode: (w^T y)^2 / (||w||^2 sum y^2)
    np.testing.assert_allclose(f.model.err, err, rtol=1e-6, atol=1e-12)


def test_the_greedy_mistake_is_the_peer_libraries_too() -> None:
    u = coloured_input(1000)
    y = simulate(QUADRATIC, u, noise_std=1e-3)
    names, _, _ = _peer(y, u, 2, 2, 2, 5)
    assert "u(k-2)" in names and "y(k-2)" not in names
    s = Structure(ny=2, nu=2, degree=2)
    f = fit_narx(y, u, FitConfig(structure=s, n_terms=5, method="ofr", remove_dc=False))
    assert f.model.term_names == names
    g = fit_narx(y, u, FitConfig(structure=s, n_terms=5, method="iofr"))
    assert set(g.model.term_names) - {"const"} == {Term.parse(n).name for n in QUADRATIC}


@pytest.mark.slow
def test_agreement_on_the_paper_speed_structure() -> None:
    """ny = 30, nu = 40, quadratic (2556 candidates), 15 terms."""
    rng = np.random.default_rng(8)
    n = 1040
    u = 30.0 * np.sin(2 * np.pi * 0.033 * np.arange(n)) + 5.0 * rng.standard_normal(n)
    y = simulate({"y(k-1)": 0.93, "u(k-1)": 0.004, "y(k-1)u(k-2)": 1e-4}, u, noise_std=1e-3)
    names, theta, err = _peer(y, u, 30, 40, 2, 15)
    f = fit_narx(y, u, FitConfig(n_terms=15, method="ofr", remove_dc=False))
    assert f.n_candidates == 2556
    assert f.model.term_names == names
    np.testing.assert_allclose(f.model.estimates, theta, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(f.model.err, err, rtol=1e-6, atol=1e-12)
