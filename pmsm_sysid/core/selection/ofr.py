"""Forward regression with orthogonal least squares (FROLS) and the ERR of Eq. 4 of Liu et al.
(2005).

At step i every remaining candidate p_j is orthogonalised against the terms already chosen,
w_j = p_j - sum_l (q_l^T p_j) q_l (q_l orthonormal), and the candidate with the largest

    ERR_j = g_j^2 ||w_j||^2 / S,   g_j = w_j^T r / ||w_j||^2,   S = sum_k (y(k) - ybar)^2

is taken (Eq. 4 of Liu et al. 2005; r is the current residual, so g_j^2 ||w_j||^2 = (p_j^T r)^2 /
||w_j||^2). Nothing is re-orthogonalised per candidate: two running vectors hold ``a_j = p_j^T r``
and
``s_j = ||w_j||^2`` and are updated with one projection ``c = P^T q`` per step
(``s -= c^2``, ``a -= (q^T r) c``), i.e. classical Gram-Schmidt done as BLAS-2/3 updates.
The chosen column itself is re-orthogonalised twice (CGS2) from its explicit values.

d.c. level (``remove_dc``): the paper removes the mean from y in Eq. 4. Done consistently,
that is orthogonalising everything against the constant first, so with ``remove_dc`` the
constant is always in the model (first, ERR 0: it explains no variance about the mean), y
and all candidates are centred, and the ERR values of the selected terms sum exactly to the
explained variance 1 - SSE/S of the final least-squares fit. With ``remove_dc=False`` the
constant is an ordinary candidate and S = sum y^2 (the convention of Billings' book and of
SysIdentPy, whose FROLS then chooses the same terms in the same order).

Dependence: a candidate whose orthogonalised norm falls below ``DEPENDENCE_TOL`` times its
original squared norm (||w_j||^2 <= 1e-10 ||p_j||^2) is skipped, never divided by.
Exact ties are broken by the lowest candidate index (``argmax`` takes the first).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import IdentificationError
from ..terms.regressors import Projector

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

DEPENDENCE_TOL = 1e-10
CRITERIA = ("terms", "err", "aic", "bic")


@dataclass(frozen=True)
class Start:
    """Quantities every search over one (projector, target) pair starts from."""

    ref: FloatArray  # ||p_j||^2 of the raw columns (dependence threshold reference)
    s0: FloatArray  # ||p_j||^2, or ||p_j - mean||^2 with the d.c. level removed
    a0: FloatArray  # P^T t
    t: FloatArray  # the target: y, or y - mean(y)
    remove_dc: bool

    @property
    def sst(self) -> float:
        return float(self.t @ self.t)


def start(proj: Projector, y: FloatArray, remove_dc: bool) -> Start:
    """Column norms and the target's projections (centred with ``remove_dc``)."""
    y = np.asarray(y, dtype=np.float64)
    ref = proj.norms2()
    if remove_dc:
        sums = proj.project(np.ones_like(y))
        s0 = ref - sums * (sums / len(y))
        t = y - y.mean()
    else:
        s0, t = ref.copy(), y.copy()
    return Start(ref=ref, s0=s0, a0=proj.project(t), t=t, remove_dc=remove_dc)


@dataclass(frozen=True)
class OfrResult:
    """Selected candidates in order, with the ERR of each and the residual path."""

    selected: IntArray  # candidate indices, forced terms first
    err: FloatArray  # ERR of each selected term (0 for the forced constant)
    sse: FloatArray  # residual sum of squares of the nested models, see ``sizes``
    sst: float  # denominator of ERR
    remove_dc: bool
    n_forced: int
    n_skipped: int  # candidates skipped as numerically dependent when selection ended
    basis_proj: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))  # P^T q_i rows
    rcoef: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))  # p_s = sum r_is q_i

    @property
    def n_params(self) -> int:
        return len(self.selected)

    @property
    def sizes(self) -> IntArray:
        """Number of parameters of the model whose SSE is ``sse[i]`` (sse[0] = sst)."""
        return np.arange(len(self.sse), dtype=np.intp) + (1 if self.remove_dc else 0)


@dataclass
class _State:
    """Running quantities of one forward regression."""

    a: FloatArray  # p_j^T r
    s: FloatArray  # ||w_j||^2
    ref: FloatArray  # ||p_j||^2 (threshold reference)
    usable: NDArray[np.bool_]
    r: FloatArray
    q: FloatArray  # (rows, capacity) orthonormal basis of the chosen terms
    rcoef: FloatArray  # (capacity, capacity) column i: coefficients of term i in q
    proj_rows: list[FloatArray]
    n_q: int = 0


def _state(st0: Start, capacity: int) -> _State:
    usable = st0.s0 > DEPENDENCE_TOL * st0.ref
    q = np.empty((len(st0.t), capacity), dtype=np.float64, order="F")
    return _State(a=st0.a0.copy(), s=st0.s0.copy(), ref=st0.ref, usable=usable,
                  r=st0.t.copy(), q=q, rcoef=np.zeros((capacity, capacity)), proj_rows=[])


def _orthonormal(st: _State, w: FloatArray) -> tuple[FloatArray, float, FloatArray]:
    """Re-orthogonalise w against the chosen basis twice (CGS2).

    Returns q, ||w_orth||^2 and the coefficients of w on the previous basis vectors."""
    basis = st.q[:, : st.n_q]
    coef = np.zeros(st.n_q)
    for _ in range(2):
        if st.n_q:
            c = basis.T @ w
            w = w - basis @ c
            coef += c
    nw2 = float(w @ w)
    return (w / np.sqrt(nw2) if nw2 > 0 else w), nw2, coef


def _take(proj: Projector, st: _State, j: int, remove_dc: bool, update: bool) -> float | None:
    """Add candidate j to the basis; return q^T r (None if it proved dependent).

    ``update=False`` skips the projection of the new basis vector (last step of a search
    that keeps no basis)."""
    w = proj.columns(np.array([j], dtype=np.intp))[:, 0]
    if remove_dc:
        w = w - w.mean()
    st.usable[j] = False
    q, nw2, coef = _orthonormal(st, w)
    if not nw2 > DEPENDENCE_TOL * st.ref[j]:
        return None
    g = float(q @ st.r)
    st.r -= g * q
    st.q[:, st.n_q] = q
    st.rcoef[: st.n_q, st.n_q] = coef
    st.rcoef[st.n_q, st.n_q] = np.sqrt(nw2)
    st.n_q += 1
    if update:
        c = proj.project(q)
        st.proj_rows.append(c)
        st.s -= c * c
        st.a -= g * c
        st.usable &= st.s > DEPENDENCE_TOL * st.ref
    return g


def _best(st: _State) -> int | None:
    crit = np.full(len(st.a), -1.0)
    np.divide(st.a * st.a, st.s, out=crit, where=st.usable)
    j = int(np.argmax(crit))
    return j if crit[j] > 0 else None


def frols(
    proj: Projector,
    y: FloatArray,
    n_terms: int,
    *,
    remove_dc: bool = True,
    constant_index: int | None = 0,
    rho: float | None = None,
    forced: Sequence[int] = (),
    keep_basis: bool = False,
    init: Start | None = None,
) -> OfrResult:
    """Select up to ``n_terms`` candidates by largest ERR (Eq. 4 of Liu et al. 2005).

    ``y`` is the regression target aligned with the projector's rows. With ``remove_dc`` the
    constant (``constant_index``, required) is forced first. ``forced`` candidates are taken
    next in the given order. ``rho`` stops early once 1 - sum(ERR) < rho. ``keep_basis``
    stores P^T q_i for every basis vector and the triangular coefficients (for iOFR);
    ``init`` reuses :func:`start` quantities computed before.
    """
    if remove_dc and constant_index is None:
        raise IdentificationError("removing the d.c. level needs a constant candidate")
    if n_terms < 1:
        raise IdentificationError(f"need at least one term (got {n_terms})")
    st0 = init if init is not None else start(proj, y, remove_dc)
    forced = [int(j) for j in forced]
    run = _Run(proj, _state(st0, min(len(forced) + n_terms, proj.n_candidates, len(st0.t))),
               st0.sst, remove_dc, keep_basis)
    if not run.sst > 0:
        raise IdentificationError("the output is constant: nothing to explain")
    if remove_dc:  # the d.c. level: centring already removed it (no basis vector)
        run.st.usable[constant_index] = False
        run.selected.append(int(constant_index))  # type: ignore[arg-type]
        run.err.append(0.0)
    for j in forced:
        if not run.add(j, last=False):
            raise IdentificationError(f"forced candidate {j} is linearly dependent")
    run.greedy(n_terms, rho)
    return run.result()


class _Run:
    """One forward regression: the running state and the selection so far."""

    def __init__(self, proj: Projector, st: _State, sst: float, remove_dc: bool,
                 keep_basis: bool) -> None:
        self.proj, self.st, self.sst = proj, st, sst
        self.remove_dc, self.keep_basis = remove_dc, keep_basis
        self.selected: list[int] = []
        self.err: list[float] = []
        self.sse = [sst]
        self.n_first = 0

    def add(self, j: int, last: bool) -> bool:
        g = _take(self.proj, self.st, j, self.remove_dc, update=self.keep_basis or not last)
        if g is None:
            return False
        self.selected.append(j)
        self.err.append(g * g / self.sst)
        self.sse.append(float(self.st.r @ self.st.r))
        return True

    def greedy(self, n_terms: int, rho: float | None) -> None:
        """Largest-ERR steps until n_terms more, 1 - sum ERR < rho, or nothing is left."""
        self.n_first = first = len(self.selected)
        cap = self.st.q.shape[1]
        while len(self.selected) - first < n_terms and self.st.n_q < cap:
            if rho is not None and len(self.selected) > first and 1.0 - sum(self.err) < rho:
                break
            best = _best(self.st)
            if best is None:
                break
            last = len(self.selected) - first + 1 >= n_terms or self.st.n_q + 1 >= cap
            self.add(best, last=last)

    def result(self) -> OfrResult:
        k, keep = self.st.n_q, self.keep_basis
        return OfrResult(
            selected=np.array(self.selected, dtype=np.intp), err=np.array(self.err),
            sse=np.array(self.sse), sst=self.sst, remove_dc=self.remove_dc,
            n_forced=self.n_first,
            n_skipped=int(np.count_nonzero(~self.st.usable)) - len(self.selected),
            basis_proj=np.array(self.st.proj_rows) if keep else np.zeros((0, 0)),
            rcoef=self.st.rcoef[:k, :k].copy() if keep else np.zeros((0, 0)),
        )


def information_criterion(sse: FloatArray, n_obs: int, n_params: IntArray, kind: str) -> FloatArray:
    """AIC = N ln(SSE/N) + 2p, BIC = N ln(SSE/N) + p ln N, for each model size."""
    if kind not in ("aic", "bic"):
        raise IdentificationError(f"unknown information criterion '{kind}' (aic, bic)")
    penalty = 2.0 if kind == "aic" else float(np.log(n_obs))
    out: FloatArray = n_obs * np.log(np.maximum(sse, 1e-300) / n_obs) + penalty * n_params
    return out


@dataclass(frozen=True)
class LsFit:
    """Least-squares estimates of y = X theta with standard deviations."""

    theta: FloatArray
    std: FloatArray
    sse: float
    residuals: FloatArray


def least_squares(x: FloatArray, y: FloatArray) -> LsFit:
    """theta by Householder QR; std = sqrt(sigma^2 diag((X^T X)^-1)), sigma^2 = SSE/(N-p)."""
    n, p = x.shape
    if p == 0:
        raise IdentificationError("no candidate term is usable on these data: every candidate "
                                  "is zero or linearly dependent")
    if n <= p:
        raise IdentificationError(f"{p} terms need more than {p} samples (got {n})")
    qmat, rmat = np.linalg.qr(x)
    diag = np.abs(np.diag(rmat))
    if not np.all(diag > 1e-13 * max(float(diag.max()), 1e-300)):
        raise IdentificationError("selected terms are linearly dependent")
    theta = np.linalg.solve(rmat, qmat.T @ y)
    res = y - x @ theta
    sse = float(res @ res)
    rinv = np.linalg.solve(rmat, np.eye(p))
    std = np.sqrt(sse / (n - p) * np.einsum("ij,ij->i", rinv, rinv))
    return LsFit(theta=theta, std=std, sse=sse, residuals=res)
