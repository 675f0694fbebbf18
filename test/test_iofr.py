"""The refined search (iOFR): exact recovery of known systems where greedy FROLS fails, and
the exchange formula against brute-force least squares."""

from __future__ import annotations

import numpy as np
import pytest
from narx_systems import (
    CUBIC,
    LINEAR,
    QUADRATIC,
    WITH_CONSTANT,
    coloured_input,
    names,
    simulate,
    white_input,
)

from pmsm_sysid.core.selection.identify import FitConfig, fit_narx
from pmsm_sysid.core.selection.iofr import _Problem, iofr
from pmsm_sysid.core.selection.ofr import frols, least_squares, start
from pmsm_sysid.core.terms.candidates import candidate_set
from pmsm_sysid.core.terms.model import Structure
from pmsm_sysid.core.terms.regressors import ExplicitRegressors, lag_base, target

SYSTEMS = {"linear": (LINEAR, 1), "quadratic": (QUADRATIC, 2), "cubic": (CUBIC, 3),
           "constant": (WITH_CONSTANT, 2)}


def _input(kind: str, n: int, scale: float) -> np.ndarray:
    return white_input(n) if kind == "white" else scale * coloured_input(n)


def _check_recovery(coeffs: dict[str, float], fit_names: list[str], est: np.ndarray) -> None:
    got = dict(zip(fit_names, est, strict=True))
    extra = set(got) - names(coeffs)
    assert set(got) - {"const"} == names(coeffs) - {"const"}, f"chose {sorted(got)}"
    if "const" in extra:  # the d.c. level is always estimated; it must be ~0 here
        assert abs(got["const"]) < 5e-3
    for n, v in coeffs.items():
        assert got[n] == pytest.approx(v, rel=0.01), n


def test_the_issue_example_greedy_fails_iofr_recovers() -> None:
    """y(k)=0.6y(k-1)-0.2y(k-2)+0.8u(k-1)+0.25y(k-1)u(k-2)-0.3u(k-2)^2, 5 terms asked."""
    u = coloured_input(1000)
    y = simulate(QUADRATIC, u, noise_std=1e-3)
    s = Structure(ny=2, nu=2, degree=2)
    greedy = fit_narx(y, u, FitConfig(structure=s, n_terms=5, method="ofr", remove_dc=False))
    assert "u(k-2)" in greedy.model.term_names  # the greedy mistake, reproduced
    assert "y(k-2)" not in greedy.model.term_names
    for dc in (False, True):
        f = fit_narx(y, u, FitConfig(structure=s, n_terms=5, method="iofr", remove_dc=dc))
        _check_recovery(QUADRATIC, f.model.term_names, f.model.estimates)
        assert "u(k-2)" in f.greedy_terms  # it started from the same wrong greedy path


@pytest.mark.parametrize("kind", ["white", "coloured"])
@pytest.mark.parametrize("system", list(SYSTEMS))
@pytest.mark.parametrize("remove_dc", [True, False])
def test_exact_term_set_and_1_percent_coefficients(system: str, kind: str,
                                                  remove_dc: bool) -> None:
    coeffs, degree = SYSTEMS[system]
    u = _input(kind, 1000, 0.4 if degree == 3 else 1.0)
    y = simulate(coeffs, u, noise_std=1e-3)
    n = len(coeffs) - (1 if "const" in coeffs and remove_dc else 0)
    s = Structure(ny=2, nu=2, degree=max(degree, 2))
    f = fit_narx(y, u, FitConfig(structure=s, n_terms=n, method="iofr", remove_dc=remove_dc))
    _check_recovery(coeffs, f.model.term_names, f.model.estimates)


@pytest.mark.parametrize("system,lags", [("quadratic", 6), ("cubic", 3), ("linear", 8)])
def test_recovery_in_larger_candidate_sets(system: str, lags: int) -> None:
    coeffs, degree = SYSTEMS[system]
    u = _input("coloured", 1500, 0.4 if degree == 3 else 1.0)
    y = simulate(coeffs, u, noise_std=1e-3, seed=3)
    s = Structure(ny=lags, nu=lags, degree=max(degree, 2))
    f = fit_narx(y, u, FitConfig(structure=s, n_terms=len(coeffs), method="iofr"))
    _check_recovery(coeffs, f.model.term_names, f.model.estimates)
    assert f.n_candidates == candidate_set(s).n_candidates


def _small(seed: int):
    u = coloured_input(200, seed=seed)
    y = simulate(QUADRATIC, u, noise_std=0.1, seed=seed) + 0.5
    s = Structure(ny=3, nu=3, degree=2)
    cs = candidate_set(s)
    return cs, ExplicitRegressors(lag_base(y, u, s), cs), target(y, s)


@pytest.mark.parametrize("remove_dc", [True, False])
def test_swap_formula_equals_brute_force_least_squares(remove_dc: bool) -> None:
    cs, proj, t = _small(0)
    st0 = start(proj, t, remove_dc)
    path = frols(proj, t, 5, remove_dc=remove_dc, keep_basis=True, init=st0)
    pb = _Problem(proj, st0, 0, path)
    on_path = [int(j) for j in path.selected[(1 if remove_dc else 0):]]
    # two terms whose P^T p_s rows come from the FROLS basis, two projected on demand
    free = [on_path[1], on_path[3], *[j for j in (5, 9, 17, 26) if j not in on_path][:2]]
    assert len(free) == 4
    sw = pb.swaps(free)
    fixed = [np.ones(len(t))] if remove_dc else []

    def sse(cols: list[int]) -> float:
        x = np.column_stack([*fixed, proj.matrix[:, cols]])
        return least_squares(x, t).sse

    assert sw.sse == pytest.approx(sse(free), rel=1e-9)
    for i in range(len(free)):
        assert sw.remove[i] == pytest.approx(sse(free[:i] + free[i + 1:]), rel=1e-9)
        for j in range(cs.n_candidates):
            if j in free or (remove_dc and j == 0):
                assert not np.isfinite(sw.swap[i, j])
                continue
            new = free.copy()
            new[i] = j
            assert sw.swap[i, j] == pytest.approx(sse(new), rel=1e-7, abs=1e-9 * pb.sst)
    for j in [c for c in range(1, cs.n_candidates) if c not in free][:4]:
        assert sw.add[j] == pytest.approx(sse([*free, j]), rel=1e-8)


@pytest.mark.parametrize("seed", range(6))
def test_iofr_never_worse_than_greedy_at_the_same_size(seed: int) -> None:
    _cs, proj, t = _small(seed)
    for n in (3, 6):
        g = frols(proj, t, n)
        r = iofr(proj, t, n)
        assert len(r.ofr.selected) == len(g.selected)
        assert r.ofr.sse[-1] <= g.sse[-1] * (1 + 1e-12)
        # ERR of the refined set, in its own ERR order, still sums to the explained variance
        ls = least_squares(proj.matrix[:, r.ofr.selected], t)
        assert np.sum(r.ofr.err) == pytest.approx(1 - ls.sse / r.ofr.sst, rel=1e-9)
