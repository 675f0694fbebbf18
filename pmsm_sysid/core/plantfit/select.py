"""Forward regression over the effect library, ranked by ERR (Eq. 4 of Liu et al. 2005), with
significance.

At each step every candidate group (one effect: one column, or a sin/cos pair per harmonic)
is orthogonalised against the effects chosen so far and scored by its error reduction ratio
``ERR_g = ||P_g y||² / ||y||²`` -- Eq. 4 with the group's orthogonal columns summed, and with
the mean kept in ``y`` so that a force offset can be found. The best member of each family
(best pitch, best Stribeck velocity) is then put to a nested F-test after AR prewhitening
(:mod:`.stats`), Bonferroni-corrected for every candidate still in the library (each
independent pitch and Stribeck velocity counts as one test). Among the families that pass
``p < alpha`` and explain at least ``min_share`` of the mismatch energy, the one with the
largest ERR is accepted; the search stops when none passes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .estimate import remainder
from .kinematics import EquationData, thinned
from .library import (
    INSTRUMENTED,
    Effect,
    Family,
    Phases,
    columns,
    families,
    family_chunks,
)
from .stats import NestedTest, lstsq, nested_f_test

FloatArray = NDArray[np.float64]

ALPHA = 1e-3
MIN_SHARE = 0.01
MAX_EFFECTS = 6
HARMONICS = (2, 3, 4)
SUBHARMONICS = (2, 3)
#: Families whose members are the same pitches (:func:`.library.pitch_grid`).
PERIODIC = ("cogging", "thrust_ripple")


@dataclass(frozen=True)
class Step:
    """One accepted (or the first refused) step of the forward regression."""

    effect: Effect
    err: float
    share: float
    test: NestedTest
    n_tests: float
    accepted: bool

    @property
    def significance(self) -> float:
        """-log10 of the Bonferroni-corrected p-value."""
        return -self.test.corrected_log10_p(self.n_tests)


@dataclass(frozen=True)
class Candidates:
    """Families with their filtered columns (float32 cache) and Gram blocks on one segment."""

    families: tuple[Family, ...]
    cols: tuple[NDArray[np.float32], ...]
    grams: tuple[FloatArray, ...]
    gys: tuple[FloatArray, ...]

    @classmethod
    def build(cls, data: EquationData, exclude: tuple[str, ...] = ()) -> Candidates:
        """Columns filtered a chunk at a time, Grams accumulated from the float64 chunk,
        the float32 cache filled in place: the only copy of a family's columns kept.

        Families of the same pitches (cogging, ripple) are built side by side, a chunk of
        each in turn, sharing the travel gains and phases of the chunk's pitches
        (:func:`.library.raw_columns`)."""
        fams = tuple(families(data, exclude))
        cols = [np.empty((len(f.members), data.n, f.members[0].width), dtype=np.float32)
                for f in fams]
        grams = [np.empty((len(f.members), f.members[0].width, f.members[0].width))
                 for f in fams]
        gys = [np.empty((len(f.members), f.members[0].width)) for f in fams]
        for group in _same_pitches(fams):
            kept: Phases = {}
            for chunks in zip(*(family_chunks(fams[i], data, kept) for i in group),
                              strict=True):
                for i, (start, c) in zip(group, chunks, strict=True):
                    stop = start + len(c)
                    grams[i][start:stop] = np.einsum("knm,knp->kmp", c, c)
                    gys[i][start:stop] = np.einsum("knm,n->km", c, data.y)
                    cols[i][start:stop] = c
                kept.clear()  # the next chunk has other pitches
        return cls(fams, tuple(cols), tuple(grams), tuple(gys))


def _same_pitches(fams: tuple[Family, ...]) -> list[tuple[int, ...]]:
    """The families' indices in order, those of cogging and ripple together (where the
    first of them is) when their members have the same pitches and width (so the same
    chunks), the others alone."""
    at = {f.name: i for i, f in enumerate(fams)}
    pair = tuple(at[n] for n in PERIODIC if n in at)
    same = len({(tuple(e.pitch_m for e in fams[i].members), fams[i].members[0].width)
                for i in pair}) == 1
    if len(pair) < 2 or not same:
        return [(i,) for i in range(len(fams))]
    return [pair if i == min(pair) else (i,) for i in range(len(fams)) if i not in pair
            or i == min(pair)]


def _family_err(cands: Candidates, i: int, q: FloatArray, qy: FloatArray,
                yy: float, y: FloatArray | None = None) -> FloatArray:
    """ERR of every member of family ``i`` after the span of ``q`` (Gram updates only;
    ``y``: a target other than the one the cache was built for)."""
    gram, rhs = cands.grams[i], cands.gys[i]
    if y is not None:
        rhs = np.einsum("knm,n->km", cands.cols[i], y.astype(np.float32)).astype(np.float64)
    if q.shape[1]:
        qg = np.einsum("nr,knm->krm", q.astype(np.float32), cands.cols[i]).astype(np.float64)
        gram = gram - np.einsum("krm,krp->kmp", qg, qg)
        rhs = rhs - np.einsum("krm,r->km", qg, qy)
    m = gram.shape[1]
    scale = np.trace(gram, axis1=1, axis2=2)[:, None, None]
    sol = np.linalg.solve(gram + (1e-10 * scale + 1e-300) * np.eye(m), rhs[..., None])[..., 0]
    err: FloatArray = np.einsum("km,km->k", sol, rhs) / yy
    return err


def share_of(y: FloatArray, base: FloatArray, extra: FloatArray,
             total: float | None = None) -> float:
    """Unwhitened ERR of ``extra`` after ``base``: its share of the mismatch energy
    (``total``, default that of ``y``)."""
    _, r0 = lstsq(base, y)
    _, r1 = lstsq(np.hstack([base, extra]), y)
    return float(r0 @ r0 - r1 @ r1) / (float(y @ y) if total is None else total)


def left_after(chosen: list[Effect], data: EquationData) -> FloatArray:
    """The mismatch with the instruments' remainder of the chosen effects taken out
    (:func:`.estimate.remainder`): regressed on the chosen columns it leaves the
    corrected plant's equation error, so a later candidate cannot take an effect's force
    that its weak instrument missed."""
    if data.inst is None or not any(e.name in INSTRUMENTED for e in chosen):
        return data.y
    beta, _ = lstsq(_stack(chosen, data), data.y)
    out: FloatArray = data.y - remainder(tuple(chosen), beta, data)
    return out


def score_step(data: EquationData, cands: Candidates, chosen: list[Effect], alpha: float,
               min_share: float) -> list[Step]:
    """Score every remaining family once; return its best member's step, best ERR first."""
    y = left_after(chosen, data)
    base = _stack(chosen, data)
    q = np.linalg.qr(base)[0] if base.shape[1] else np.zeros((len(y), 0))
    names = {e.name for e in chosen}
    n_tests = sum(f.n_independent for f in cands.families if f.name not in names)
    out = []
    qy = q.T @ y
    yy = float(data.y @ data.y)
    for i, fam in enumerate(cands.families):
        if fam.name in names:
            continue
        errs = _family_err(cands, i, q, qy, yy, None if y is data.y else y)
        k = int(np.argmax(errs))
        err = float(errs[k])
        effect = fam.members[k]
        extra = columns(effect, data)
        test = nested_f_test(y, base, extra)
        share = share_of(y, base, extra, yy)
        ok = test.corrected_log10_p(n_tests) < math.log10(alpha) and share >= min_share
        out.append(Step(effect, err, share, test, n_tests, ok))
    return sorted(out, key=lambda s: -s.err)


def forward_select(data: EquationData, cands: Candidates, alpha: float = ALPHA,
                   min_share: float = MIN_SHARE, max_effects: int = MAX_EFFECTS,
                   first: list[Step] | None = None) -> tuple[list[Step], list[Step]]:
    """Accepted steps in order, and the scores of the refused candidates at the last step.

    ``first``: :func:`score_step` of ``data`` with nothing chosen, when the caller has it
    (the ranking): the first step is taken from it instead of being scored again."""
    chosen: list[Effect] = []
    steps: list[Step] = []
    while len(chosen) < min(max_effects, len(cands.families)):
        scored = first if first is not None and not chosen \
            else score_step(data, cands, chosen, alpha, min_share)
        passing = [s for s in scored if s.accepted]
        if not passing:
            return steps, scored
        step = passing[0]
        if step.effect.name == "cogging":
            grown = grow_cogging(step.effect, data, _stack(chosen, data),
                                 left_after(chosen, data), alpha, min_share)
            step = replace(step, effect=grown)
        steps.append(step)
        chosen.append(step.effect)
    return steps, []


def _passes(y: FloatArray, X: FloatArray, cols: FloatArray, n_tests: int, alpha: float,
            min_share: float, total: float) -> bool:
    """Significant (Bonferroni over ``n_tests``) and explains ``min_share`` of ``total``."""
    _, r0 = lstsq(X, y)
    _, r1 = lstsq(np.hstack([X, cols]), y)
    share = float(r0 @ r0 - r1 @ r1) / total
    return bool(nested_f_test(y, X, cols).corrected_log10_p(n_tests) < math.log10(alpha)
                and share >= min_share)


def grow_cogging(cog: Effect, data: EquationData, others: FloatArray, y: FloatArray,
                 alpha: float, min_share: float) -> Effect:
    """``cog`` with its significant harmonics, or at a sub-harmonic pitch.

    Harmonics 2-4 and sub-harmonic pitches 2p, 3p (a true pitch whose fundamental is weak;
    tried only if the travel covers one such period) are each put to the nested F-test
    against the other effects plus the cogging found so far, Bonferroni-corrected over the
    five tried, and must explain ``min_share`` of the mismatch.
    """
    n_tests = len(HARMONICS) + len(SUBHARMONICS)
    total = float(data.y @ data.y)
    orders = cog.orders
    while True:  # harmonics enter one at a time, the strongest first (they correlate
        X = np.hstack([others, columns(replace(cog, orders=orders), data)])  # on short travel)
        tried = [(share_of(y, X, c), h, c) for h in HARMONICS if h not in orders
                 for c in [columns(replace(cog, orders=(h,)), data)]]
        if not tried:
            break
        _, h, c = max(tried, key=lambda t: t[0])
        if not _passes(y, X, c, n_tests, alpha, min_share, total):
            break
        orders = tuple(sorted((*orders, h)))
    travel = float(np.ptp(thinned(data, data.x)))
    for m in SUBHARMONICS:
        if m * cog.pitch_m > travel:
            break
        cols = columns(replace(cog, pitch_m=cog.pitch_m * m, orders=(1,)), data)
        if _passes(y, X, cols, n_tests, alpha, min_share, total):
            return replace(cog, pitch_m=cog.pitch_m * m,
                           orders=tuple(sorted({1} | {m * h for h in orders})))
    return replace(cog, orders=orders)


def _stack(effects: list[Effect], data: EquationData) -> FloatArray:
    if not effects:
        return np.zeros((data.n, 0))
    return np.hstack([columns(e, data) for e in effects])
