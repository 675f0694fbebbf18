"""Candidate term sets of a polynomial NARX model (Eqs. 3 and 5 of Liu et al. 2005).

The candidates are every monomial of degree 0..``degree`` in the *base signals*

    y(k-1) ... y(k-ny),  u(k-d) ... u(k-d-nu+1)

(plus the constant, the empty product, when ``structure.constant``). Each candidate is stored
as a row of ``degree`` indices into the *extended base* ``[1, y(k-1), ..., u(k-d-nu+1)]``;
index 0 is the column of ones, so a linear term ``y(k-3)`` is the row ``(0, 3)`` in a
quadratic set. Rows are the lexicographic ``combinations_with_replacement`` of the extended
base, which gives the order: constant, linear terms (y lags, then u lags), then products.
With ``nb = ny + nu`` base signals there are ``C(nb + degree, degree)`` candidates including
the constant: the paper's speed structure (ny = 30, nu = 40, degree 2) gives 2556.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations_with_replacement
from math import comb

import numpy as np
from numpy.typing import NDArray

from ..errors import IdentificationError
from .model import Structure, Term

IntArray = NDArray[np.intp]

#: Largest candidate set built on request (protects memory: an explicit degree-3 matrix of
#: this many columns over 1000 samples is already 1.6 GB in float64).
MAX_CANDIDATES = 200_000


def count_candidates(structure: Structure) -> int:
    """Number of candidate terms of ``structure`` (closed form, no enumeration)."""
    nb = structure.ny + structure.nu
    return comb(nb + structure.degree, structure.degree) - (0 if structure.constant else 1)


@dataclass(frozen=True)
class CandidateSet:
    """All candidate terms of one structure, in a fixed order (see module docstring)."""

    structure: Structure
    index: IntArray  # (M, degree) rows of indices into the extended base, non-decreasing
    base_terms: tuple[Term, ...]  # the extended base: const, y(k-1)..y(k-ny), u(k-d)..
    terms: tuple[Term, ...]
    term_names: tuple[str, ...] = ()

    @property
    def n_candidates(self) -> int:
        return len(self.terms)

    @property
    def n_base(self) -> int:
        """Number of extended base columns (ones + ny + nu)."""
        return len(self.base_terms)

    @property
    def names(self) -> list[str]:
        return list(self.term_names)

    def position(self, term: Term | str) -> int:
        """Index of ``term`` (a Term or a paper-style name) in this set."""
        t = Term.parse(term) if isinstance(term, str) else term
        try:
            return _positions(self.structure)[t]
        except KeyError as exc:
            raise IdentificationError(
                f"term {t.name} is not a candidate of {self.structure}"
            ) from exc

    @property
    def constant_index(self) -> int | None:
        """Index of the constant candidate, or None if the set has none."""
        return 0 if self.structure.constant else None


def base_terms(structure: Structure) -> tuple[Term, ...]:
    """The extended base: constant, y(k-1)..y(k-ny), u(k-d)..u(k-d-nu+1)."""
    ys = [Term((("y", i),)) for i in range(1, structure.ny + 1)]
    us = [Term((("u", structure.delay + j),)) for j in range(structure.nu)]
    return (Term(()), *ys, *us)


@lru_cache(maxsize=32)
def candidate_set(structure: Structure) -> CandidateSet:
    """The candidate set of ``structure`` (cached: one enumeration per structure)."""
    m = count_candidates(structure)
    if m > MAX_CANDIDATES:
        raise IdentificationError(
            f"{m} candidate terms (ny={structure.ny}, nu={structure.nu}, degree="
            f"{structure.degree}) exceed the limit of {MAX_CANDIDATES}; reduce lags or degree"
        )
    base = base_terms(structure)
    nb = len(base)
    rows = np.array(
        list(combinations_with_replacement(range(nb), structure.degree)), dtype=np.intp
    ).reshape(-1, structure.degree)
    if not structure.constant:
        rows = rows[1:]  # the all-zero row (the constant) is always first
    terms = tuple(
        Term(tuple(f for i in row if i for f in base[i].factors)) for row in rows.tolist()
    )
    rows.setflags(write=False)
    return CandidateSet(structure=structure, index=rows, base_terms=base, terms=terms,
                        term_names=tuple(t.name for t in terms))


@lru_cache(maxsize=32)
def _positions(structure: Structure) -> dict[Term, int]:
    return {t: i for i, t in enumerate(candidate_set(structure).terms)}
