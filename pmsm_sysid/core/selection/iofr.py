"""Refined term selection: iterative OFR by exact term exchange.

Plain FROLS (:mod:`.ofr`) is greedy: once a term is in, it stays, so on correlated
regressors an early wrong choice is never undone (e.g. ``u(k-2)`` instead of ``y(k-2)``).
After Guo, Guo, Billings & Wei (2015, "An iterative orthogonal forward regression
algorithm", Int. J. Systems Science 46(5)), which re-examines every selected term, this
module re-examines every *pair* (selected term i, candidate j) exactly and cheaply:

With S the selected set, Q R = P_S (thin QR) and r the residual, the span of S without term i
loses one direction, the unit vector v_i = Q R^{-T} e_i / ||R^{-T} e_i|| (orthogonal to the
other selected terms). Removing i therefore adds (v_i^T y)^2 to the SSE, and the candidate j
then explains (p_j^T r + (v_i^T p_j)(v_i^T y))^2 / (||p_j - Q Q^T p_j||^2 + (v_i^T p_j)^2).
All of v_i^T p_j come from C = Q^T P (one projection per selected term) through R^{-1}, so
one pass costs about as much as one FROLS run, for all n x M swaps at once:

    SSE(i -> j) = SSE + (v_i^T y)^2 - (a_j + B_ij c_i)^2 / (s_j + B_ij^2).

The best swap is made while it lowers the SSE by more than 1e-9 of itself plus 1e-13 of
the total sum of squares (a floor above rounding; the SSE strictly decreases, so the search
cannot cycle), up to ``max_swaps``. With an AIC/BIC
criterion the model size is then also moved by one term (the best removal or addition)
whenever that lowers the criterion, and the exchange repeats. Finally the chosen set is
ordered by ERR (a FROLS pass restricted to it) so ERR values keep their Eq. 4 meaning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_triangular

from ..errors import IdentificationError
from ..terms.regressors import DenseProjector, Projector
from .ofr import DEPENDENCE_TOL, OfrResult, Start, frols, information_criterion, start

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

MAX_SWAPS = 100
_REL_GAIN = 1e-9  # a move must lower the SSE by this fraction of itself ...
_ABS_GAIN = 1e-13  # ... and by this fraction of the total sum of squares (rounding floor)


@dataclass
class _Swaps:
    """Exact effect of removing/adding/exchanging terms of the current set."""

    sse: float
    remove: FloatArray  # SSE after removing term i
    add: FloatArray  # SSE after adding candidate j (inf where not allowed)
    swap: FloatArray  # (n, M) SSE after replacing term i by candidate j


class _Problem:
    """The candidate set, target and a cache of P^T p_s for the selected columns s.

    Swapping needs C = Q^T P for the current set's orthonormal basis Q. With P_S = Q R,
    C = R^{-T} (P_S^T P), and the rows p_s^T P are cached: those of the FROLS path come free
    from its stored basis projections (p_s = sum_i r_is q_i), so an exchange costs one new
    projection per swapped-in candidate instead of one per selected term.
    """

    def __init__(self, proj: Projector, st0: Start, const: int | None, path: OfrResult):
        self.proj, self.remove_dc = proj, st0.remove_dc
        self.ref, self.s0, self.a0, self.t = st0.ref, st0.s0, st0.a0, st0.t
        self.sst = st0.sst
        self.allowed = self.s0 > DEPENDENCE_TOL * self.ref
        if self.remove_dc and const is not None:
            self.allowed[const] = False
        self._rows: dict[int, FloatArray] = {}
        n_fixed = 1 if self.remove_dc else 0
        if len(path.basis_proj):
            for k, j in enumerate(path.selected[n_fixed:].tolist()):
                self._rows[j] = path.rcoef[: k + 1, k] @ path.basis_proj[: k + 1]

    def cols(self, free: list[int]) -> FloatArray:
        c = self.proj.columns(np.array(free, dtype=np.intp))
        return c - c.mean(axis=0) if self.remove_dc else c

    def rows(self, free: list[int]) -> FloatArray:
        """P^T p_s (centred p_s with the d.c. level removed) for each s in ``free``."""
        for j in free:
            if j not in self._rows:
                self._rows[j] = self.proj.project(self.cols([j])[:, 0])
        return np.stack([self._rows[j] for j in free])

    def sse(self, free: list[int]) -> float:
        q, _ = np.linalg.qr(self.cols(free))
        r = self.t - q @ (q.T @ self.t)
        return float(r @ r)

    def swaps(self, free: list[int]) -> _Swaps:
        q, rmat = np.linalg.qr(self.cols(free))
        diag = np.abs(np.diag(rmat))
        if np.any(diag <= 1e-12 * diag.max()):
            raise IdentificationError("selected terms became linearly dependent")
        z = q.T @ self.t
        r = self.t - q @ z
        sse = float(r @ r)
        cq = solve_triangular(rmat, self.rows(free), trans="T")  # Q^T P
        a = self.a0 - cq.T @ z
        s = np.maximum(self.s0 - np.einsum("ij,ij->j", cq, cq), 0.0)
        rinv = solve_triangular(rmat, np.eye(len(free)))
        dn = np.linalg.norm(rinv, axis=1)
        b = (rinv @ cq) / dn[:, None]
        vy = (rinv @ z) / dn
        ok = self.allowed.copy()
        ok[free] = False
        add = np.full(len(a), np.inf)
        good = ok & (s > DEPENDENCE_TOL * self.ref)
        add[good] = sse - a[good] ** 2 / s[good]
        den = s[None, :] + b * b
        num = a[None, :] + b * vy[:, None]
        swap = np.full(den.shape, np.inf)
        mask = ok[None, :] & (den > DEPENDENCE_TOL * self.ref[None, :])
        swap[mask] = (sse + vy[:, None] ** 2 - num**2 / np.where(mask, den, 1.0))[mask]
        return _Swaps(sse=sse, remove=sse + vy**2, add=add, swap=swap)


def _exchange(pb: _Problem, free: list[int], max_swaps: int) -> tuple[list[int], int]:
    """Best single swaps until none lowers the SSE; returns the set and the swap count."""
    n_swaps = 0
    while free and n_swaps < max_swaps:
        sw = pb.swaps(free)
        i, j = np.unravel_index(int(np.argmin(sw.swap)), sw.swap.shape)
        if not sw.swap[i, j] < sw.sse * (1.0 - _REL_GAIN) - _ABS_GAIN * pb.sst:
            break
        free[int(i)] = int(j)
        n_swaps += 1
    return free, n_swaps


def _resize(pb: _Problem, free: list[int], n_obs: int, kind: str, n_fixed: int,
            max_free: int) -> bool:
    """Drop or add one term if that lowers AIC/BIC (never beyond ``max_free`` terms besides
    the constant: ``n_terms`` is the maximum); return True if the set changed."""
    sw = pb.swaps(free)
    n = len(free) + n_fixed
    i_rm, j_add = int(np.argmin(sw.remove)), int(np.argmin(sw.add))
    sizes = np.array([n, n - 1, n + 1], dtype=np.intp)
    cand = np.array([sw.sse, sw.remove[i_rm] if len(free) > 1 else np.inf, sw.add[j_add]])
    ic = information_criterion(np.maximum(cand, 1e-300), n_obs, sizes, kind)
    ic[~np.isfinite(cand)] = np.inf
    best = int(np.argmin(ic))
    if best == 1 and ic[1] < ic[0]:
        del free[i_rm]
        return True
    if best == 2 and ic[2] < ic[0] and n + 1 < n_obs and len(free) < max_free:
        free.append(j_add)
        return True
    return False


@dataclass(frozen=True)
class IofrResult:
    """The refined selection, its ERR ordering, and how much refining it took."""

    ofr: OfrResult  # the final set in ERR order (same fields as plain FROLS)
    greedy: OfrResult  # the initial FROLS selection
    n_swaps: int
    n_resizes: int


def _truncate(res: OfrResult, n_free: int) -> OfrResult:
    """The greedy path cut to ``n_free`` selected terms besides the forced constant."""
    n_fixed = 1 if res.remove_dc else 0
    k = min(n_free, len(res.sse) - 1)
    return OfrResult(selected=res.selected[: n_fixed + k], err=res.err[: n_fixed + k],
                     sse=res.sse[: k + 1], sst=res.sst, remove_dc=res.remove_dc,
                     n_forced=res.n_forced, n_skipped=res.n_skipped)


def _target_size(path: OfrResult, n_terms: int, criterion: str, rho: float | None,
                 n_obs: int) -> int:
    """Number of terms (besides the forced constant) the criterion asks for on the path."""
    avail = min(n_terms, len(path.sse) - 1)
    if criterion == "err" and rho is not None:
        unexplained = path.sse[1 : avail + 1] / path.sst
        hit = np.flatnonzero(unexplained < rho)
        return int(hit[0]) + 1 if len(hit) else avail
    if criterion in ("aic", "bic"):
        ic = information_criterion(path.sse, n_obs, path.sizes, criterion)[1 : avail + 1]
        return int(np.argmin(ic)) + 1
    return avail


def _prune(pb: _Problem, free: list[int], size: int) -> list[int]:
    """Backward elimination: drop the term whose removal raises the SSE least.

    One QR of the columns, then each removal re-triangularises R without that column
    (P_S' = Q R' = (Q Q2) R2 with R' = Q2 R2), so the loop works on n x n matrices only."""
    free = list(free)
    if len(free) <= max(size, 1):
        return free
    q, rmat = np.linalg.qr(pb.cols(free))
    z = q.T @ pb.t
    while len(free) > max(size, 1):
        rinv = solve_triangular(rmat, np.eye(len(free)))
        vy = (rinv @ z) / np.linalg.norm(rinv, axis=1)
        i = int(np.argmin(vy * vy))
        del free[i]
        q2, rmat = np.linalg.qr(np.delete(rmat, i, axis=1))
        z = q2.T @ z
    return free


def iofr(
    proj: Projector,
    y: FloatArray,
    n_terms: int,
    *,
    remove_dc: bool = True,
    constant_index: int | None = 0,
    criterion: str = "terms",
    rho: float | None = None,
    max_swaps: int = MAX_SWAPS,
) -> IofrResult:
    """Over-select by FROLS, prune back, then exchange (and resize for AIC/BIC).

    1. FROLS to twice the wanted size (the path also fixes the size for ``err``/``aic``/
       ``bic`` exactly as plain FROLS would); 2. backward elimination to the size, dropping
    each time the term whose removal raises the SSE least; start from that set or from
    the plain FROLS set of the same size, whichever has the lower SSE (so the result is
    never worse than FROLS); 3. exact single-term exchanges while one lowers the SSE;
    4. for AIC/BIC, one-term resizes while they lower the criterion, each followed by
    exchanges.
    """
    y = np.asarray(y, dtype=np.float64)
    st0 = start(proj, y, remove_dc)
    path = frols(proj, y, 2 * n_terms, remove_dc=remove_dc, constant_index=constant_index,
                 keep_basis=True, init=st0)
    n_fixed = 1 if remove_dc else 0
    if len(path.selected) <= n_fixed:
        raise IdentificationError("no candidate term is usable on these data: every candidate "
                                  "is zero or linearly dependent")
    size = _target_size(path, n_terms, criterion, rho, len(y))
    pb = _Problem(proj, st0, constant_index, path)
    pruned = _prune(pb, [int(j) for j in path.selected[n_fixed : n_fixed + 2 * size]], size)
    greedy = [int(j) for j in path.selected[n_fixed : n_fixed + size]]
    free = pruned if pb.sse(pruned) <= path.sse[size] else greedy
    free, n_swaps = _exchange(pb, free, max_swaps)
    n_resizes = 0
    while criterion in ("aic", "bic") and n_resizes < n_terms and n_swaps < max_swaps:
        if not _resize(pb, free, len(y), criterion, n_fixed, n_terms):
            break
        n_resizes += 1
        free, more = _exchange(pb, free, max_swaps - n_swaps)
        n_swaps += more
    return IofrResult(ofr=_in_err_order(pb, y, free, remove_dc, constant_index),
                      greedy=_truncate(path, size if criterion == "err" else n_terms),
                      n_swaps=n_swaps, n_resizes=n_resizes)


def _in_err_order(
    pb: _Problem, y: FloatArray, free: list[int], remove_dc: bool, const: int | None
) -> OfrResult:
    """FROLS restricted to the chosen columns: gives each its ERR in selection order."""
    idx = ([const] if remove_dc and const is not None else []) + free
    sub = DenseProjector(pb.proj.columns(np.array(idx, dtype=np.intp)))
    res = frols(sub, y, len(free), remove_dc=remove_dc, constant_index=0 if remove_dc else None)
    mapped = np.array(idx, dtype=np.intp)[res.selected]
    return OfrResult(selected=mapped, err=res.err, sse=res.sse, sst=res.sst,
                     remove_dc=remove_dc, n_forced=res.n_forced, n_skipped=0)
