"""Candidate term sets and regressor matrices against closed forms and naive products."""

from __future__ import annotations

from collections import Counter
from itertools import combinations_with_replacement
from math import comb

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pmsm_sysid.core.errors import DataError, IdentificationError
from pmsm_sysid.core.terms.candidates import MAX_CANDIDATES, candidate_set, count_candidates
from pmsm_sysid.core.terms.model import Structure, Term
from pmsm_sysid.core.terms.regressors import (
    DenseProjector,
    ExplicitRegressors,
    ProductGram,
    candidate_matrix,
    lag_base,
    make_projector,
    target,
    term_matrix,
)


def test_paper_speed_structure_has_2556_candidates() -> None:
    cs = candidate_set(Structure(ny=30, nu=40, degree=2, delay=1, constant=True))
    assert cs.n_candidates == 2556
    # closed form over the 70 lagged signals: 1 constant + 70 linear + C(71, 2) quadratic,
    # counted on the terms the set holds, by degree and by lag range
    assert Counter(t.degree for t in cs.terms) == {0: 1, 1: 70, 2: comb(71, 2)}
    assert {f for t in cs.terms for f in t.factors} == (
        {("y", i) for i in range(1, 31)} | {("u", j) for j in range(1, 41)})
    assert len(set(cs.terms)) == 2556


def test_paper_position_structure() -> None:
    cs = candidate_set(Structure(ny=10, nu=10, degree=2))
    assert cs.n_candidates == comb(22, 2) == 231


@settings(max_examples=30, deadline=None)
@given(ny=st.integers(0, 6), nu=st.integers(0, 6), degree=st.integers(1, 3),
       delay=st.integers(1, 3), constant=st.booleans())
def test_count_matches_enumeration(ny: int, nu: int, degree: int, delay: int,
                                   constant: bool) -> None:
    if ny + nu == 0:
        return
    s = Structure(ny=ny, nu=nu, degree=degree, delay=delay, constant=constant)
    cs = candidate_set(s)
    # independent enumeration of the monomials of degree 1..degree (+ constant)
    base = [("y", i) for i in range(1, ny + 1)] + [("u", delay + j) for j in range(nu)]
    expected = {Term(c) for d in range(1, degree + 1)
                for c in combinations_with_replacement(base, d)}
    if constant:
        expected.add(Term(()))
    assert set(cs.terms) == expected
    assert cs.n_candidates == len(expected) == count_candidates(s)


def test_names_follow_the_seed_tables() -> None:
    cs = candidate_set(Structure(ny=10, nu=40, degree=2))
    for name in ("const", "y(k-1)", "u(k-10)", "y(k-1)u(k-10)", "y(k-10)^2", "u(k-40)^2"):
        assert cs.terms[cs.position(name)].name == name
    assert cs.names[0] == "const"
    assert cs.names[1:3] == ["y(k-1)", "y(k-2)"]
    # delay shifts the input lags
    cs3 = candidate_set(Structure(ny=1, nu=2, degree=1, delay=3))
    assert cs3.names == ["const", "y(k-1)", "u(k-3)", "u(k-4)"]


def test_unknown_term_and_huge_set_are_refused() -> None:
    cs = candidate_set(Structure(ny=2, nu=2, degree=2))
    with pytest.raises(IdentificationError, match="not a candidate"):
        cs.position("y(k-9)")
    big = Structure(ny=60, nu=60, degree=3)
    assert count_candidates(big) > MAX_CANDIDATES
    with pytest.raises(IdentificationError, match="exceed the limit"):
        candidate_set(big)


def test_lag_base_alignment() -> None:
    rng = np.random.default_rng(3)
    y, u = rng.standard_normal(50), rng.standard_normal(50)
    s = Structure(ny=3, nu=4, degree=2, delay=2)  # u lags 2..5 -> max lag 5
    x = lag_base(y, u, s)
    assert x.shape == (45, 8)
    for row, k in enumerate(range(5, 50)):
        assert x[row, 0] == 1.0
        assert list(x[row, 1:4]) == [y[k - 1], y[k - 2], y[k - 3]]
        assert list(x[row, 4:]) == [u[k - 2], u[k - 3], u[k - 4], u[k - 5]]
    assert np.array_equal(target(y, s), y[5:])
    with pytest.raises(DataError, match="too few"):
        lag_base(y[:5], u[:5], s)


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_candidate_matrix_equals_naive_products(degree: int) -> None:
    rng = np.random.default_rng(degree)
    y, u = rng.standard_normal(60), rng.standard_normal(60)
    s = Structure(ny=3, nu=3, degree=degree, constant=degree != 2)
    cs = candidate_set(s)
    x = lag_base(y, u, s)
    p = candidate_matrix(x, cs)
    assert p.flags.f_contiguous
    naive = np.empty_like(p)
    for j, term in enumerate(cs.terms):
        col = np.ones(len(x))
        for var, lag in term.factors:
            col = col * (y if var == "y" else u)[s.max_lag - lag: len(y) - lag]
        naive[:, j] = col
    np.testing.assert_allclose(p, naive, rtol=1e-14, atol=1e-14)
    idx = np.array([0, len(cs.terms) // 2, len(cs.terms) - 1])
    np.testing.assert_allclose(term_matrix(x, cs, idx), naive[:, idx], rtol=1e-14)


def test_product_gram_equals_explicit_matrix() -> None:
    rng = np.random.default_rng(7)
    y, u = rng.standard_normal(400), 3.0 + rng.standard_normal(400)
    for degree in (1, 2):
        s = Structure(ny=5, nu=6, degree=degree)
        cs = candidate_set(s)
        x = lag_base(y, u, s)
        g, e = ProductGram(x, cs), ExplicitRegressors(x, cs)
        w = rng.standard_normal(x.shape[0])
        np.testing.assert_allclose(g.norms2(), e.norms2(), rtol=1e-12)
        np.testing.assert_allclose(g.project(w), e.project(w), rtol=1e-10, atol=1e-10)
        idx = np.array([3, 1, len(cs.terms) - 1])
        np.testing.assert_array_equal(g.columns(idx), e.columns(idx))
        d = DenseProjector(e.matrix)
        np.testing.assert_allclose(d.project(w), e.project(w))
    assert isinstance(make_projector(x, cs), ProductGram)
    s3 = Structure(ny=2, nu=2, degree=3)
    assert isinstance(make_projector(lag_base(y, u, s3), candidate_set(s3)), ExplicitRegressors)
    with pytest.raises(IdentificationError, match="unknown regressor engine"):
        make_projector(x, cs, "magic")
