"""Polynomial NARX model terms and their regressors: the candidate set of lagged inputs
and outputs and their products, and the model they form (Liu et al. 2005, Eq. 8).
"""

from .candidates import CandidateSet, candidate_set, count_candidates
from .model import NarxModel, Structure, Term
from .regressors import candidate_matrix, make_projector, term_matrix

__all__ = [
    "CandidateSet", "NarxModel", "Structure", "Term", "candidate_matrix", "candidate_set",
    "count_candidates", "make_projector", "term_matrix"
]
