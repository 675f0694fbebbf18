"""The effects a recording shows beyond a reference plant: select, confirm, re-estimate, name.

The recording is split into estimation and held-out data (or paired with a held-out
recording) and each part becomes equation-error data against the reference plant
(:mod:`.kinematics`). Then:

1. **Name** -- forward regression over the library (:mod:`.select`): ERR ranking (Eq. 4 of
   Liu et al. 2005), prewhitened F-tests with a Bonferroni correction for every candidate
   and pitch searched, and a floor on the share of the mismatch explained.
2. **Model** -- nonlinear refinement, look-alike disambiguation and held-out confirmation
   (:mod:`.modelling`).
3. **Re-estimate** -- without a held-out recording, the confirmed effects are re-estimated
   on the whole recording and a backward pass drops what is no longer significant.
4. **Report** -- each effect's parameters with standard errors (:mod:`.translate`), its
   significance given all the others, its share of the mismatch, its held-out test and a
   confidence (:class:`.found.FoundEffect`).

``diagnose`` runs this against the user's plant and goes on to locate what is left;
fitting a plant from a recording runs it with the mass and viscous terms searched too.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..errors import DiagnoseError, PlantError
from ..physics.plant import Plant
from ..recording.signals import Recording, check_finite
from ..recording.spans import MAX_SAMPLES, Excerpt, excerpt_of, plan_spans
from .estimate import Fit, design, refine
from .feedback import FEEDBACK_Z, feedback_z
from .found import FoundEffect, capped
from .kinematics import EquationData, FilterSpec, choose_filter, kinematic_mode
from .library import MIN_PERIODS, Effect, periods_seen
from .modelling import Alternative, Model, confirmed_model
from .parts import equation_data_parts
from .profile import Profile, profiles, settle_friction
from .reading import reading_gap, reading_noise
from .select import ALPHA, MAX_EFFECTS, MIN_SHARE, Candidates, Step, forward_select, score_step
from .stats import HeldOutTest, ar_whitener, f_logsf, lstsq, whiten
from .translate import corrected_plant, effect_params

#: Share of a single recording used for estimation; the rest is held out.
SPLIT = 0.7
#: Which look-alike comparison (:func:`.modelling.build_model`) an effect's name belongs to.
LOOKALIKE = {"thrust_lag": "thrust_lag", "transport_delay": "thrust_lag",
             "stribeck_friction": "stribeck_friction", "coulomb_friction": "stribeck_friction"}


@dataclass(frozen=True)
class FitOptions:
    """Thresholds of the selection (defaults are the documented ones)."""

    alpha: float = ALPHA
    min_share: float = MIN_SHARE
    split: float = SPLIT
    max_effects: int = MAX_EFFECTS
    max_samples: int = MAX_SAMPLES
    """Samples used at most of each recording (spans spread over a longer one)."""


@dataclass(frozen=True)
class Segments:
    """Equation data of the estimation, held-out and (if split) whole recording."""

    est: EquationData
    val: EquationData
    full: EquationData | None
    recs: dict[str, Recording]
    feedback: float = 0.0
    parts: dict[str, tuple[Recording, ...]] = field(default_factory=dict)
    """The contiguous parts of ``recs`` (one each, unless spans of a long recording)."""
    used: dict[str, Any] = field(default_factory=dict)
    """What part of the recordings was used (:meth:`.spans.Excerpt.describe`)."""
    thrust_noise_n: float = 0.0
    """The thrust reading's white noise (N rms, an upper bound: :mod:`.reading`)."""

    def pieces(self, name: str) -> tuple[Recording, ...]:
        """The contiguous parts of segment ``name`` (``estimation``, ``validation``)."""
        return self.parts.get(name) or (self.recs[name],)

    @property
    def closed_loop(self) -> bool:
        """The thrust answers the sensor noise (see :func:`.kinematics.feedback_z`)."""
        return self.feedback > FEEDBACK_Z


def _filter_for(spec: FilterSpec, fs: float) -> FilterSpec:
    """The same cut-off at another sample rate (decimation and edge recomputed)."""
    return replace(spec, decimation=max(1, int(fs / (2.5 * spec.cutoff_hz))),
                   edge=int(np.ceil(3.0 * fs / spec.cutoff_hz)))


def excerpt_for(rec: Recording | Excerpt, max_samples: int, split: float | None) -> Excerpt:
    """The spans of ``rec`` a fit uses (:func:`..recording.spans.plan_spans`); an
    :class:`Excerpt` (the spans already read) as it is."""
    if isinstance(rec, Excerpt):
        return rec
    return excerpt_of(rec, plan_spans(len(rec), max_samples, split))


def _split(ex: Excerpt, split: float) -> tuple[tuple[Recording, ...], tuple[Recording, ...]]:
    """The parts of one recording before and after the cut of the whole recording (a part
    across the cut -- the whole recording, when it is used whole -- is split there)."""
    cut = int(split * ex.total)
    if cut < 10 or ex.total - cut < 10:
        raise DiagnoseError(f"{ex.total} samples cannot be split for held-out data")
    before: list[Recording] = []
    after: list[Recording] = []
    for (a, b), part in zip(ex.ranges(), ex.parts, strict=True):
        if b <= cut:
            before.append(part)
        elif a >= cut:
            after.append(part)
        else:
            before.append(part.window(0, cut - a))
            after.append(part.window(cut - a, b - a))
    if not before or not after:
        raise DiagnoseError(f"the spans of {ex.total} samples leave no held-out data")
    return tuple(before), tuple(after)


def estimation_parts(ex: Excerpt, held: Excerpt | None,
                     split: float = SPLIT) -> tuple[Recording, ...]:
    """The parts of ``ex`` the estimation uses: all of them beside a held-out recording
    (``held``), else those before the cut at ``split`` (:func:`segments` splits the same)."""
    return ex.parts if held is not None else _split(ex, split)[0]


def _whole(parts: tuple[Recording, ...], ex: Excerpt, first: bool) -> Recording:
    """The parts as one recording: a window of the excerpt's joined recording (no copy)."""
    n = sum(len(p) for p in parts)
    return ex.joined.window(0, n) if first else ex.joined.window(ex.used - n, ex.used)


def segments(plant: Plant, real: Recording | Excerpt, validate: Recording | Excerpt | None,
             split: float = SPLIT, max_samples: int = MAX_SAMPLES) -> Segments:
    """Split (or pair) the recordings and build their equation-error data.

    A recording longer than ``max_samples`` is used in spans spread over it
    (:func:`..recording.spans.plan_spans`); an :class:`Excerpt` says which were read.
    """
    ex = excerpt_for(real, max_samples, split if validate is None else None)
    vex = None if validate is None else excerpt_for(validate, max_samples, None)
    for e in (ex, vex):
        if e is not None:
            check_finite(e.joined)
    if vex is None:
        before, after = _split(ex, split)  # as estimation_parts
        parts = {"estimation": before, "validation": after}
        recs = {"estimation": _whole(before, ex, True), "validation": _whole(after, ex, False)}
        used = {"recording": ex.describe(held_out=len(after) if not ex.whole else 0)}
    else:
        parts = {"estimation": ex.parts, "validation": vex.parts}
        recs = {"estimation": ex.joined, "validation": vex.joined}
        used = {"recording": ex.describe(), "validate_recording": vex.describe()}
    est_parts = parts["estimation"]
    fs = est_parts[0].sample_rate_hz
    spec = choose_filter([p.speed for p in est_parts], fs)
    vfs = recs["validation"].sample_rate_hz
    vspec = spec if vfs == fs else _filter_for(spec, vfs)
    fb = feedback_z(est_parts)
    closed = fb > FEEDBACK_Z
    mode = kinematic_mode(est_parts, spec, closed)
    est = equation_data_parts(plant, est_parts, spec, mode, closed)
    noise = reading_noise(est_parts, closed)
    gap = reading_gap(noise, est)
    if gap:
        est = equation_data_parts(plant, est_parts, spec, mode, closed, gap)
    val = equation_data_parts(plant, parts["validation"], vspec, mode, closed, gap)
    full = equation_data_parts(plant, ex.parts, spec, mode, closed, gap) if vex is None \
        else None
    return Segments(est, val, full, recs, fb, parts, used, float(np.sqrt(noise)))


@dataclass(frozen=True)
class EffectsFit:
    """What :func:`fit_effects` found: the confirmed model, its final estimate, the effects."""

    segs: Segments
    model: Model
    """Refined and confirmed on the estimation data (held-out numbers stay honest)."""
    final: Fit
    """The same effects re-estimated on :attr:`data` and pruned."""
    data: EquationData
    """The whole recording when it was split, else the estimation recording."""
    found: tuple[FoundEffect, ...]
    dropped: tuple[Effect, ...]
    """Significant on the estimation data but not confirmed on held-out data."""
    ranking: tuple[Step, ...]
    """The library's candidates ranked by ERR on the reference plant's residual."""
    n_tests: float


def fit_effects(plant: Plant, segs: Segments, opts: FitOptions | None = None) -> EffectsFit:
    """Select, confirm, re-estimate and name the effects of ``segs`` beyond ``plant``."""
    opts = opts or FitOptions()
    cands = Candidates.build(segs.est, exclude=("thrust_lag",) if segs.closed_loop else ())
    n_tests = sum(f.n_independent for f in cands.families)
    ranking = score_step(segs.est, cands, [], opts.alpha, opts.min_share)
    steps, _ = forward_select(segs.est, cands, opts.alpha, opts.min_share, opts.max_effects,
                              first=ranking)
    chosen = settle_friction(tuple(s.effect for s in steps), segs.est, n_tests, opts.alpha,
                             opts.min_share)
    model, held, dropped = confirmed_model(chosen, segs.est, segs.val, opts.alpha,
                                           opts.min_share)
    final, fdata = _final(model, segs)
    final, held = _prune(final, fdata, list(held), n_tests, opts.alpha)
    final, profs = profiles(final, fdata)
    found = _named(final, fdata, plant, held, model.alternatives, n_tests, opts.alpha,
                   profs)
    return EffectsFit(segs, model, final, fdata, tuple(found), tuple(dropped),
                      tuple(ranking), n_tests)


def drop_one(fit: Fit, data: EquationData, n_tests: float) -> list[float]:
    """Significance (-log10 corrected p) of each effect given all the others."""
    X, fixed = design(fit.effects, data)
    poly = ar_whitener(data.y - fixed - X @ fit.beta)
    _, r1 = lstsq(whiten(poly, X), whiten(poly, data.y - fixed))  # GLS, like the reduced fits
    sse1 = float(r1 @ r1)
    dof = max(1, len(r1) - X.shape[1] - len(fit.eta))
    out = []
    for k in range(len(fit.effects)):
        rest = fit.effects[:k] + fit.effects[k + 1:]
        Xr, fr = design(rest, data)
        _, r0 = lstsq(whiten(poly, Xr), whiten(poly, data.y - fr))
        q = max(1, fit.effects[k].width)
        f = max(0.0, (float(r0 @ r0) - sse1) / q) / (sse1 / dof)
        out.append(capped(f_logsf(f, q, dof) / np.log(10.0)
                          + np.log10(max(n_tests, 1.0))))
    return out


def _shares(fit: Fit, data: EquationData) -> list[float]:
    """Sequential share of the mismatch energy (ERR in the selection order)."""
    yy = float(data.y @ data.y)
    prev = yy
    out = []
    for k in range(1, len(fit.effects) + 1):
        X, fixed = design(fit.effects[:k], data)
        _, r = lstsq(X, data.y - fixed)
        sse = float(r @ r)
        out.append(max(0.0, (prev - sse) / yy))
        prev = sse
    return out


def confidence(sig: float, held: HeldOutTest | None, alt: Alternative | None, alpha: float,
               identified: bool = True) -> str:
    """high: overwhelming on both data sets (the held-out recording included), no
    look-alike tie and a shape the data can tell (a pitch met twice over the travel);
    moderate: significant and significantly better on held-out data (or tied, or not
    identified); low: otherwise."""
    tie = alt is not None and abs(alt.delta_chi2) < 3.84
    if held is not None and held.p_value < 1e-3 and sig >= 10.0 and not tie and identified:
        return "high"
    if sig >= -np.log10(alpha) and (held is None or held.significant):
        return "moderate"
    return "low"


def _named(fit: Fit, data: EquationData, plant: Plant, held: list[Any],
           alts: dict[str, Alternative], n_tests: float, alpha: float,
           profs: dict[int, Profile] | None = None) -> list[FoundEffect]:
    sigs = drop_one(fit, data, n_tests)
    shares = _shares(fit, data)
    tradeoff = any(not p.identified for p in (profs or {}).values())
    out = []
    for k, e in enumerate(fit.effects):
        params, std = effect_params(fit, k, plant)
        alt = alts.get(LOOKALIKE.get(e.name, ""))
        notes = []
        alt_d = None
        if alt is not None and alt.name != e.name:
            alt_d = alt.to_dict()
            if abs(alt.delta_chi2) < 3.84:
                notes.append(f"indistinguishable from {alt.name} in these data "
                             f"(Δχ² = {alt.delta_chi2:.2f} < 3.84)")
        periods = periods_seen(e, data)
        if periods < MIN_PERIODS:
            notes.append(f"the travel covers {periods:.1f} periods of this pitch: no phase "
                         "of it is met twice, so a smooth curve over position (a local "
                         "force) explains it as well -- not identified as periodic")
        prof = (profs or {}).get(k)
        if prof is not None and not prof.identified:
            notes.append(prof.note())
        traded = e.name in ("coulomb_friction", "viscous_error") and tradeoff
        if traded:
            notes.append("its level trades off with the Stribeck hump, whose static force "
                         "and velocity these data do not tell apart")
        identified = periods >= MIN_PERIODS and (prof is None or prof.identified) \
            and not traded
        out.append(FoundEffect(e.name, params, std, sigs[k], shares[k], held[k],
                               confidence(sigs[k], held[k], alt, alpha, identified),
                               tuple(notes), alt_d,
                               None if prof is None else prof.to_dict()))
    return out


def correct(plant: Plant, named: list[tuple[str, dict[str, Any]]]) -> tuple[Plant, list[str]]:
    """``plant`` with the named effects applied, or ``plant`` and a note if that is invalid."""
    try:
        return corrected_plant(plant, [(n, p) for n, p in named if n != "unexplained"])
    except PlantError as exc:
        return plant, [f"the corrected plant is not valid ({exc}); the nominal one is kept"]


def _final(model: Model, segs: Segments) -> tuple[Fit, EquationData]:
    """The confirmed model re-estimated on the whole recording when it was split."""
    if segs.full is None or not model.fit.effects:
        return model.fit, segs.est
    X, fixed = design(model.fit.effects, segs.full)
    _, r = lstsq(X, segs.full.y - fixed)
    return refine(model.fit.effects, segs.full, ar_whitener(r)), segs.full


def _prune(fit: Fit, data: EquationData, held: list[Any], n_tests: float,
           alpha: float) -> tuple[Fit, list[Any]]:
    """Backward elimination on the final data: drop effects no longer significant."""
    while fit.effects:
        sigs = drop_one(fit, data, n_tests)
        k = int(np.argmin(sigs))
        if sigs[k] >= -np.log10(alpha):
            break
        rest = fit.effects[:k] + fit.effects[k + 1:]
        X, fixed = design(rest, data)
        _, r = lstsq(X, data.y - fixed)
        fit = refine(rest, data, ar_whitener(r))
        held = held[:k] + held[k + 1:]
    return fit, held
