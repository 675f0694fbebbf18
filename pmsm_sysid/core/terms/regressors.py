"""Lagged and product regressor matrices for polynomial NARX candidates.

Rows are the time instants k = L .. N-1 with L = ``structure.max_lag`` (the first L samples
only feed the lags). The *extended base* matrix ``X`` (rows x (1 + ny + nu), Fortran order)
holds a column of ones and the lagged signals; every candidate is a product of ``degree``
base columns (see :mod:`.candidates`).

Forward regression only ever needs three things from the candidate matrix P: the squared
column norms, the products ``P^T w`` for a few vectors w, and the few selected columns.
Two engines provide them behind one protocol:

* :class:`ProductGram` (degree <= 2) never forms P. For a vector w,
  ``(P^T w)_j = sum_k w(k) x_a(k) x_b(k)`` is entry (a, b) of ``X^T diag(w) X``: one small
  matrix product ((1+ny+nu)^2 x rows) that stays in cache, then a gather. For the paper's
  structure that is 71 x 71 x 1000 multiply-adds per projection instead of streaming a
  2556 x 1000 matrix through memory, and no extra memory beyond two base-sized buffers.
* :class:`ExplicitRegressors` (any degree) fills P once into a preallocated Fortran-order
  buffer, block by block, without temporaries; projections are BLAS ``gemv``.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, IdentificationError
from .candidates import CandidateSet
from .model import Structure

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Largest explicit candidate matrix built (bytes); above this ``identify`` refuses clearly.
MAX_MATRIX_BYTES = 512 * 2**20
#: slabs of the implicit product (upper triangle only); 4-6 is fastest on the paper's 71
GRAM_BLOCKS = 5


def lag_base(y: FloatArray, u: FloatArray, structure: Structure) -> FloatArray:
    """Extended base matrix: ones, y(k-1)..y(k-ny), u(k-d)..u(k-d-nu+1), rows k = L..N-1."""
    y = np.asarray(y, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if y.ndim != 1 or u.shape != y.shape:
        raise DataError(f"y and u must be 1-D of equal length (got {y.shape} and {u.shape})")
    n, lag = len(y), structure.max_lag
    if n <= lag:
        raise DataError(f"{n} samples are too few for a maximum lag of {lag}")
    rows = n - lag
    x = np.empty((rows, 1 + structure.ny + structure.nu), dtype=np.float64, order="F")
    x[:, 0] = 1.0
    for i in range(1, structure.ny + 1):
        x[:, i] = y[lag - i : n - i]
    for j in range(structure.nu):
        shift = structure.delay + j
        x[:, 1 + structure.ny + j] = u[lag - shift : n - shift]
    return x


def target(y: FloatArray, structure: Structure) -> FloatArray:
    """The regression target y(k), k = L..N-1, aligned with :func:`lag_base` rows."""
    return np.ascontiguousarray(np.asarray(y, dtype=np.float64)[structure.max_lag :])


class Projector(Protocol):
    """What forward regression needs from a candidate matrix P (rows x M)."""

    n_rows: int
    n_candidates: int

    def norms2(self) -> FloatArray:
        """Squared column norms ||p_j||^2."""
        ...

    def project(self, w: FloatArray) -> FloatArray:
        """P^T w (length M)."""
        ...

    def columns(self, idx: IntArray) -> FloatArray:
        """The columns ``idx`` of P as a (rows x len(idx)) Fortran-order array."""
        ...


def _pairs(cset: CandidateSet) -> tuple[IntArray, IntArray]:
    idx = cset.index
    if idx.shape[1] == 1:
        return np.zeros(len(idx), dtype=np.intp), idx[:, 0].copy()
    if idx.shape[1] == 2:
        return idx[:, 0].copy(), idx[:, 1].copy()
    raise IdentificationError("ProductGram handles degree 1 and 2 only")


class ProductGram:
    """Implicit candidate matrix of degree <= 2 (see module docstring).

    Only the upper triangle of X^T diag(w) X is needed (candidates have a <= b), so the
    product is done as ``GRAM_BLOCKS`` trapezoidal slabs (rows of block i against columns
    from the block's start on): about 60% of the full product's work."""

    def __init__(self, base: FloatArray, cset: CandidateSet) -> None:
        self.base = np.asfortranarray(base, dtype=np.float64)
        self.n_rows, nb = self.base.shape
        self.n_candidates = cset.n_candidates
        self._i0, self._i1 = _pairs(cset)
        self._flat = self._i0 * nb + self._i1  # into a full nb x nb Gram
        self._work = np.empty_like(self.base)
        edges = np.unique(np.linspace(0, nb, min(GRAM_BLOCKS, nb) + 1).astype(np.intp))
        self._edges = edges
        sizes = [(int(edges[k + 1] - edges[k]), int(nb - edges[k])) for k in range(len(edges) - 1)]
        offsets = np.cumsum([0] + [r * c for r, c in sizes])
        self._buf = np.empty(int(offsets[-1]))
        self._slabs = [self._buf[offsets[k] : offsets[k + 1]].reshape(sizes[k])
                       for k in range(len(sizes))]
        blk = np.searchsorted(edges, self._i0, side="right") - 1
        start = edges[blk]
        width = nb - start
        self._slab_flat = offsets[blk] + (self._i0 - start) * width + (self._i1 - start)

    def _gather(self, gram: FloatArray) -> FloatArray:
        out: FloatArray = gram.ravel()[self._flat]
        return out

    def norms2(self) -> FloatArray:
        sq = self.base * self.base
        return self._gather(sq.T @ sq)

    def project(self, w: FloatArray) -> FloatArray:
        np.multiply(self.base, w[:, None], out=self._work)
        e = self._edges
        for k, slab in enumerate(self._slabs):
            np.matmul(self._work[:, e[k] : e[k + 1]].T, self.base[:, e[k] :], out=slab)
        out: FloatArray = self._buf[self._slab_flat]
        return out

    def columns(self, idx: IntArray) -> FloatArray:
        idx = np.asarray(idx, dtype=np.intp)
        out = np.empty((self.n_rows, len(idx)), dtype=np.float64, order="F")
        np.multiply(self.base[:, self._i0[idx]], self.base[:, self._i1[idx]], out=out)
        return out


class DenseProjector:
    """A projector over an explicit matrix (e.g. a handful of selected columns)."""

    def __init__(self, matrix: FloatArray) -> None:
        self.matrix = np.asfortranarray(matrix, dtype=np.float64)
        self.n_rows, self.n_candidates = self.matrix.shape

    def norms2(self) -> FloatArray:
        out: FloatArray = np.einsum("ij,ij->j", self.matrix, self.matrix)
        return out

    def project(self, w: FloatArray) -> FloatArray:
        out: FloatArray = self.matrix.T @ w
        return out

    def columns(self, idx: IntArray) -> FloatArray:
        return np.asfortranarray(self.matrix[:, np.asarray(idx, dtype=np.intp)])


class ExplicitRegressors(DenseProjector):
    """The candidate matrix P, filled once into a Fortran-order buffer (any degree)."""

    def __init__(self, base: FloatArray, cset: CandidateSet) -> None:
        rows, m = base.shape[0], cset.n_candidates
        if rows * m * 8 > MAX_MATRIX_BYTES:
            raise IdentificationError(
                f"candidate matrix {rows} x {m} needs {rows * m * 8 / 2**20:.0f} MB "
                f"(limit {MAX_MATRIX_BYTES / 2**20:.0f} MB); reduce lags, degree or window"
            )
        super().__init__(candidate_matrix(base, cset))


def candidate_matrix(
    base: FloatArray, cset: CandidateSet, out: FloatArray | None = None
) -> FloatArray:
    """Fill the full candidate matrix (rows x M, Fortran order) from the base matrix.

    Rows of ``cset.index`` that share all but their last index are contiguous and their last
    index runs over a contiguous range of base columns, so each run is one broadcast
    multiply straight into ``out`` (no temporaries beyond one prefix product vector).
    """
    rows, m = base.shape[0], cset.n_candidates
    if out is None:
        out = np.empty((rows, m), dtype=np.float64, order="F")
    elif out.shape != (rows, m):
        raise IdentificationError(f"buffer shape {out.shape} != {(rows, m)}")
    idx = cset.index
    prefix = idx[:, :-1]
    change = np.flatnonzero(np.any(prefix[1:] != prefix[:-1], axis=1)) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [m]))
    for s, e in zip(starts.tolist(), stops.tolist(), strict=True):
        pv = np.ones(rows, dtype=np.float64)
        for i in prefix[s].tolist():
            if i:
                pv *= base[:, i]
        lo, hi = int(idx[s, -1]), int(idx[e - 1, -1]) + 1
        np.multiply(pv[:, None], base[:, lo:hi], out=out[:, s:e])
    return out


def make_projector(base: FloatArray, cset: CandidateSet, engine: str = "auto") -> Projector:
    """``auto``: the implicit product engine for degree <= 2, the explicit matrix otherwise."""
    if engine == "auto":
        engine = "gram" if cset.structure.degree <= 2 else "explicit"
    if engine == "gram":
        return ProductGram(base, cset)
    if engine == "explicit":
        return ExplicitRegressors(base, cset)
    raise IdentificationError(f"unknown regressor engine '{engine}' (auto, gram, explicit)")


def term_matrix(base: FloatArray, cset: CandidateSet, idx: IntArray) -> FloatArray:
    """Columns ``idx`` of the candidate matrix, any degree, without building the rest."""
    idx = np.asarray(idx, dtype=np.intp)
    out = np.ones((base.shape[0], len(idx)), dtype=np.float64, order="F")
    for c, row in enumerate(cset.index[idx].tolist()):
        for i in row:
            if i:
                out[:, c] *= base[:, i]
    return out
