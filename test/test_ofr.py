"""FROLS with the ERR of seed Eq. 4, checked against a naive greedy least-squares search,
closed forms and known simulated systems."""

from __future__ import annotations

import numpy as np
import pytest
from narx_systems import LINEAR, QUADRATIC, coloured_input, names, simulate, white_input

from pmsm_sysid.core.errors import IdentificationError
from pmsm_sysid.core.selection.identify import FitConfig, fit_narx
from pmsm_sysid.core.selection.ofr import frols, information_criterion, least_squares
from pmsm_sysid.core.terms.candidates import candidate_set
from pmsm_sysid.core.terms.model import Structure
from pmsm_sysid.core.terms.regressors import (
    DenseProjector,
    ExplicitRegressors,
    ProductGram,
    lag_base,
    target,
)


def _sse(cols: np.ndarray, y: np.ndarray) -> float:
    theta = np.linalg.lstsq(cols, y, rcond=None)[0]
    r = y - cols @ theta
    return float(r @ r)


def naive_greedy(p: np.ndarray, y: np.ndarray, n: int, remove_dc: bool) -> list[int]:
    """Forward selection by largest SSE reduction with full least squares each time."""
    chosen: list[int] = []
    base = [np.ones((len(y), 1))] if remove_dc else []
    fixed = [0] if remove_dc else []
    for _ in range(n):
        best, best_sse = -1, np.inf
        for j in range(p.shape[1]):
            if j in chosen or j in fixed:
                continue
            cols = np.column_stack([*base, p[:, [*chosen, j]]])
            s = _sse(cols, y)
            if s < best_sse - 1e-12 * abs(best_sse if np.isfinite(best_sse) else 1.0):
                best, best_sse = j, s
        chosen.append(best)
    return fixed + chosen


def _problem(seed: int = 0, n: int = 300):
    u = coloured_input(n, seed=seed)
    y = simulate(QUADRATIC, u, noise_std=0.05, seed=seed) + 0.3  # nonzero mean
    s = Structure(ny=3, nu=3, degree=2)
    cs = candidate_set(s)
    x = lag_base(y, u, s)
    return cs, ExplicitRegressors(x, cs), target(y, s)


@pytest.mark.parametrize("remove_dc", [True, False])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_selection_equals_naive_greedy_least_squares(remove_dc: bool, seed: int) -> None:
    _cs, proj, t = _problem(seed)
    res = frols(proj, t, 6, remove_dc=remove_dc)
    expected = naive_greedy(proj.matrix, t, 6, remove_dc)
    assert res.selected.tolist() == expected


@pytest.mark.parametrize("remove_dc", [True, False])
def test_err_sums_to_explained_variance(remove_dc: bool) -> None:
    cs, proj, t = _problem(4)
    res = frols(proj, t, 7, remove_dc=remove_dc)
    ls = least_squares(proj.matrix[:, res.selected], t)
    # with the d.c. level removed: explained variance about the mean; else about zero
    sst = float(np.sum((t - t.mean()) ** 2)) if remove_dc else float(t @ t)
    assert res.sst == pytest.approx(sst, rel=1e-12)
    assert np.sum(res.err) == pytest.approx(1.0 - ls.sse / sst, rel=1e-10)
    assert res.sse[-1] == pytest.approx(ls.sse, rel=1e-8)
    assert np.all(res.err >= 0)
    if remove_dc:
        assert cs.terms[res.selected[0]].is_constant and res.err[0] == 0.0


def test_first_err_is_the_squared_correlation() -> None:
    cs, proj, t = _problem(5)
    res = frols(proj, t, 1, remove_dc=True)
    j = int(res.selected[1])
    r = np.corrcoef(proj.matrix[:, j], t)[0, 1]
    assert res.err[1] == pytest.approx(r * r, rel=1e-10)
    # and it is the best single candidate
    corr2 = [np.corrcoef(proj.matrix[:, i], t)[0, 1] ** 2 for i in range(1, cs.n_candidates)]
    assert res.err[1] == pytest.approx(max(corr2), rel=1e-10)


def test_engines_choose_identically_on_the_paper_structure() -> None:
    rng = np.random.default_rng(11)
    u = np.sin(2 * np.pi * 0.033 * np.arange(1100)) + 0.2 * rng.standard_normal(1100)
    y = simulate({"y(k-1)": 1.6, "y(k-2)": -0.7, "u(k-1)": 0.3, "y(k-1)u(k-3)": 0.05}, u,
                 noise_std=1e-3)
    s = Structure()  # ny=30, nu=40, degree 2
    cs = candidate_set(s)
    x, t = lag_base(y, u, s), target(y, s)
    a = frols(ProductGram(x, cs), t, 15)
    b = frols(ExplicitRegressors(x, cs), t, 15)
    assert a.selected.tolist() == b.selected.tolist()
    np.testing.assert_allclose(a.err, b.err, rtol=1e-6, atol=1e-12)
    assert {"y(k-1)", "y(k-2)", "u(k-1)", "y(k-1)u(k-3)"} <= {cs.names[i] for i in a.selected}


def test_dependent_candidates_are_skipped_never_nan() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal(200), rng.standard_normal(200)
    mat = np.column_stack([np.ones(200), a, a, 2 * a + b, b, np.zeros(200), a + 1e-14 * b])
    y = 1.0 + 2.0 * a - b + 0.01 * rng.standard_normal(200)
    res = frols(DenseProjector(mat), y, 6, remove_dc=True)
    # a and b span everything: const + two terms; duplicates of a have the lowest index first
    assert res.selected.tolist()[:2] == [0, 1]
    assert len(res.selected) == 3
    assert np.all(np.isfinite(res.err)) and np.all(np.isfinite(res.sse))
    assert res.n_skipped == 4  # the copy of a, 2a+b or b, the zero column, a+tiny


def test_exact_ties_go_to_the_lowest_index() -> None:
    rng = np.random.default_rng(1)
    a = rng.standard_normal(100)
    mat = np.column_stack([a, a, a])
    res = frols(DenseProjector(mat), 3 * a, 3, remove_dc=False, constant_index=None)
    assert res.selected.tolist() == [0]


def test_rho_stops_at_the_first_size_that_explains_enough() -> None:
    u = white_input(600)
    y = simulate(LINEAR, u, noise_std=1e-2)
    cfg = FitConfig(structure=Structure(ny=3, nu=3, degree=2), n_terms=12, criterion="err",
                    rho=1e-3, method="ofr")
    f = fit_narx(y, u, cfg)
    n = len(f.model.terms) - 1  # besides the constant
    assert 1.0 - f.sum_err < 1e-3
    assert 1.0 - float(np.sum(f.model.err[:-1])) >= 1e-3  # one term fewer was not enough
    assert 1 <= n < 12


@pytest.mark.parametrize("kind", ["aic", "bic"])
def test_information_criteria_choose_the_minimum_and_the_true_size(kind: str) -> None:
    u = white_input(800, seed=5)
    y = simulate(LINEAR, u, noise_std=0.05, seed=5)
    s = Structure(ny=3, nu=3, degree=2)
    f = fit_narx(y, u, FitConfig(structure=s, n_terms=12, criterion=kind, method="ofr"))
    assert len(f.criterion_values) == 13  # sizes 0..12 besides the constant
    assert len(f.model.terms) - 1 == int(np.argmin(f.criterion_values))
    # plain FROLS takes y(k-3), u(k-3) before y(k-1), y(k-2) here; the refined search
    # finds the true terms and size
    g = fit_narx(y, u, FitConfig(structure=s, n_terms=12, criterion=kind, method="iofr"))
    chosen = set(g.model.term_names) - {"const"}
    assert names(LINEAR) <= chosen
    # BIC's log(N) penalty gives the exact size; AIC (penalty 2) may keep one spurious term
    spurious = chosen - names(LINEAR)
    assert len(spurious) <= (0 if kind == "bic" else 1), spurious
    ic = information_criterion(np.array([4.0, 2.0]), 100, np.array([1, 2]), "aic")
    assert ic.tolist() == pytest.approx([100 * np.log(0.04) + 2, 100 * np.log(0.02) + 4])


def test_ofr_recovers_a_linear_system_to_1_percent() -> None:
    u = white_input(1000)
    y = simulate(LINEAR, u, noise_std=1e-3)
    f = fit_narx(y, u, FitConfig(structure=Structure(ny=2, nu=2, degree=2), n_terms=4,
                                 method="ofr"))
    got = dict(zip(f.model.term_names, f.model.estimates, strict=True))
    assert set(got) - {"const"} == names(LINEAR)
    for n, v in LINEAR.items():
        assert got[n] == pytest.approx(v, rel=0.01)


def test_least_squares_std_matches_the_closed_form() -> None:
    rng = np.random.default_rng(2)
    x = rng.standard_normal((120, 3))
    y = x @ np.array([1.0, -2.0, 0.5]) + 0.1 * rng.standard_normal(120)
    fit = least_squares(x, y)
    theta = np.linalg.solve(x.T @ x, x.T @ y)
    res = y - x @ theta
    cov = (res @ res) / (120 - 3) * np.linalg.inv(x.T @ x)
    np.testing.assert_allclose(fit.theta, theta, rtol=1e-10)
    np.testing.assert_allclose(fit.std, np.sqrt(np.diag(cov)), rtol=1e-10)
    with pytest.raises(IdentificationError, match="linearly dependent"):
        least_squares(np.column_stack([x[:, 0], x[:, 0]]), y)


def test_dc_removal_needs_a_constant_and_a_nonconstant_output() -> None:
    mat = np.random.default_rng(0).standard_normal((50, 3))
    with pytest.raises(IdentificationError, match="constant candidate"):
        frols(DenseProjector(mat), mat[:, 0], 2, remove_dc=True, constant_index=None)
    with pytest.raises(IdentificationError, match="constant"):
        frols(DenseProjector(np.column_stack([np.ones(50), mat])), np.ones(50), 2)
