"""A physical plant from a recording: mass, viscous damping and the library's effects.

A plant is the rigid mass-damper ``F = M a + B v`` plus effect blocks. The mass and the
viscous coefficient are always estimated (never selected); the effects are selected as
``diagnose`` selects what a plant leaves out (:func:`.fit.fit_effects`), against the fitted
rigid plant. The equation data, its instruments for the mass and viscous terms (IDIM-IV)
and the friction calibration are all built *through* a reference plant
(:mod:`.kinematics`), so the fit iterates:

1. **Crude start.** Two-stage least squares of the parallel-filtered force on the filtered
   acceleration and speed, instrumented by the thrust's responses through mass-dampers of
   time constants from five samples to a third of the recording (lagged by the filter's
   memory under feedback), with a constant, sign(v) and the position beside them (an
   exactly linear inversion: reference mass 1 kg, no damping). It only starts the
   iteration: ordinary least squares, biased by noise and feedback, started a position
   loop at a twentieth of the mass and the iteration never recovered.
2. **Rigid iteration (IDIM-IV).** Against the rigid reference ``(M_k, B_k)`` the residual is
   regressed on the instrumented mass and viscous columns and the current effects (a
   force offset, Coulomb friction and a spring as nuisance terms in the first round); the
   reference moves to ``(M_k + ΔM, B_k + ΔB)`` until both steps are below a hundredth of
   their standard errors (at most ``MAX_ITERATIONS``). The instruments are the responses of
   mass-dampers with the reference's time constant (and half and twice it) to the
   recorded thrust, so each round makes them fit the axis better.
3. **Effects.** The library is searched against the converged rigid plant: forward
   selection by ERR, prewhitened F-tests with a Bonferroni correction, held-out
   confirmation, re-estimation on the whole recording -- the same statistics as
   ``diagnose``. The mass and viscous terms of the library are not reported as effects:
   they are the plant's own parameters. An effect's share is of the rigid plant's
   mismatch: beside a large friction a small effect must still explain ``min_share`` of
   that.
4. **Joint estimate.** Step 2 is repeated with the selected effects, all parameters
   together (nonlinear ones -- pitches, Stribeck velocity, lag -- refined by variable
   projection); standard errors are the sandwich covariance of :mod:`.estimate` (the
   mass's and viscous coefficient's included). If the mass or viscous coefficient moved by
   more than one standard error from the reference the effects were selected against (or
   the selection named a mass or viscous error), step 3 runs once more.

The fitted plant's ``sample_rate_hz`` is the recording's; winding resistance, inductance and
flux are not identified from a force balance and keep the nominal values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, InsufficientExcitationError, PlantError, PmsmSysidError
from ..physics.plant import Plant
from ..recording.signals import Recording, check_finite
from ..recording.spans import Excerpt, Parts, as_parts
from .estimate import Fit, design, refine
from .feedback import FEEDBACK_Z, feedback_z, high_band
from .fit import (
    EffectsFit,
    FitOptions,
    Segments,
    estimation_parts,
    excerpt_for,
    fit_effects,
    segments,
)
from .found import FoundEffect
from .instruments import instrumented
from .kinematics import (
    MIN_SAMPLES,
    EquationData,
    FilterSpec,
    choose_filter,
    kinematic_mode,
)
from .library import Effect
from .parts import equation_data_parts
from .stats import ar_whitener, lstsq
from .translate import _polar, corrected_plant, effect_params

FloatArray = NDArray[np.float64]

RIGID = (Effect("mass_error"), Effect("viscous_error"))
RIGID_NAMES = ("mass_error", "viscous_error")
#: Nuisance effects estimated with the mass and viscous terms before the selection: an
#: offset, Coulomb friction and a spring (under a slow sinusoidal move a spring's force is
#: in step with the acceleration and would pass for a negative mass).
START_EFFECTS = (Effect("force_offset"), Effect("coulomb_friction"), Effect("spring"))
MAX_ITERATIONS = 8
STEP_TOLERANCE = 0.01  # of a standard error
MAX_ROUNDS = 2
#: Time constants of the crude start's instrument bank.
CRUDE_TIME_CONSTANTS = 5
#: Fewest samples a plant is fitted from (both the estimation and held-out parts need the
#: equation data's minimum after the filter's edges are trimmed).
MIN_PLANT_SAMPLES = 4 * MIN_SAMPLES
#: The position must span this many times its noise for the axis to count as moving.
MOTION_FACTOR = 20.0


@dataclass(frozen=True)
class Setup:
    """What the equation data are built with, fixed for the recording (not the plant)."""

    spec: FilterSpec
    mode: str
    closed: bool
    feedback: float


@dataclass(frozen=True)
class PhysicalFit:
    """The plant fitted from a recording, with standard errors and the found effects."""

    plant: Plant
    std: dict[str, Any]
    """Standard errors with the keys and nesting of the plant file (fitted values only)."""
    found: tuple[FoundEffect, ...]
    """The library effects, parameters from the joint estimate (mass and viscous free)."""
    reference: Plant
    """The rigid plant the final equation data were built against."""
    joint: Fit
    """mass_error, viscous_error and the effects, jointly on :attr:`data`."""
    data: EquationData
    """The whole recording (with a held-out recording: the estimation recording)."""
    segs: Segments
    """Estimation and held-out equation data against :attr:`reference`."""
    est_joint: Fit
    """The joint estimate on the estimation part only (honest held-out numbers)."""
    effects_fit: EffectsFit
    """The selection (segments, ranking, confirmed model) of the last round."""
    setup: Setup
    iterations: int
    rounds: int
    notes: tuple[str, ...] = ()

    @property
    def effects(self) -> tuple[Effect, ...]:
        """The library effects of the joint estimate (mass and viscous terms left out)."""
        return self.joint.effects[len(RIGID):]


def check_identifiable(rec: Parts, label: str = "recording") -> None:
    """One clear error before any work when ``rec`` cannot identify a plant.

    A plant needs motion above the measurement noise, a thrust that varies (mass and
    viscous damping are told apart by acceleration and speed that do not move in step) and
    enough samples for an estimation and a held-out part after the filter's edges.
    ``rec`` may be the spans of a long recording (the parts used): they are judged together.
    """
    parts = as_parts(rec)
    for p in parts:
        check_finite(p)
    n, fs = sum(len(p) for p in parts), parts[0].sample_rate_hz
    thrust = np.concatenate([p.thrust for p in parts])
    if n < MIN_PLANT_SAMPLES:
        raise DataError(
            f"{label}: {n} samples ({n / fs:.3g} s) are too short to identify a plant: it "
            f"needs at least {MIN_PLANT_SAMPLES} samples of motion ({MIN_PLANT_SAMPLES / fs:.3g}"
            f" s at {fs:g} Hz), better several seconds")
    if float(np.ptp(thrust)) <= 1e-9 * max(1.0, float(np.max(np.abs(thrust)))):
        raise InsufficientExcitationError(
            f"{label}: the thrust is constant: no excitation to identify a plant from; it "
            "needs a varying thrust (a chirp, multisine, PRBS or a positioning move)")
    _check_motion(parts, label)
    try:
        spec = choose_filter([p.speed for p in parts], fs)
    except PmsmSysidError as exc:
        raise DataError(f"{label}: {exc}; a plant needs a recording of the axis moving") \
            from exc
    need = max(MIN_SAMPLES, 4 * spec.edge)
    if n * 0.3 < need:
        raise DataError(
            f"{label}: {n} samples ({n / fs:.3g} s) are too short for its slow motion "
            f"(speed band {spec.band_hz:.3g} Hz): identifying a plant needs at least "
            f"{math.ceil(need / 0.3)} samples ({need / 0.3 / fs:.3g} s)")
    _check_rigid_excitation(parts, spec, label)


def _check_motion(parts: list[Recording], label: str) -> None:
    """The position must travel well beyond its own noise (read above 0.3 fs)."""
    fs = parts[0].sample_rate_hz
    x = np.concatenate([p.position for p in parts])
    noise = float(np.std(np.concatenate([high_band(p.position, fs) for p in parts]))) \
        / math.sqrt(0.4)
    travel = float(np.ptp(x))
    if travel <= MOTION_FACTOR * noise or travel == 0.0:
        raise DataError(f"{label}: the axis does not move (its position spans {travel:.3g} m, "
                        f"within its noise of {noise:.2g} m): a plant needs a recording of "
                        "the axis moving under a varying thrust")


def _check_rigid_excitation(parts: list[Recording], spec: FilterSpec, label: str) -> None:
    """Acceleration and speed must not move in step: a constant-acceleration or
    constant-speed run cannot tell mass from damping."""
    from .zerophase import butter_sos, sosfiltfilt

    fs = parts[0].sample_rate_hz
    sos = butter_sos(spec.order, spec.cutoff_hz, fs)
    vs, acc = [], []
    for p in parts:  # within each part: nothing differentiated across a gap
        vp = sosfiltfilt(sos, np.diff(p.position) * fs)[spec.edge:-spec.edge]
        acc.append(np.diff(vp) * fs)
        vs.append(vp[1:])
    v, a = np.concatenate(vs), np.concatenate(acc)
    X = np.column_stack([np.ones(len(v)), v - v.mean(), a - a.mean()])
    scale = np.linalg.norm(X, axis=0)
    if np.any(scale[1:] <= 0):
        raise InsufficientExcitationError(
            f"{label}: the axis moves at constant speed: no acceleration to identify a mass "
            "from; it needs a varying thrust (a chirp, multisine, PRBS or a positioning move)")
    s = np.linalg.svd(X / scale, compute_uv=False)
    if s[-1] / s[0] < 1e-3:
        raise InsufficientExcitationError(
            f"{label}: acceleration and speed move in step (a single ramp): mass and damping "
            "cannot be told apart; it needs a varying thrust with reversals (a chirp, "
            "multisine, PRBS or a positioning move)")


def setup(est: Parts) -> Setup:
    """Filter, kinematic mode and loop as :func:`.fit.segments` chooses them: from the
    estimation part ``est`` (a recording, or the estimation spans of a long one;
    :func:`.fit.estimation_parts`), so the iteration and the selection see the same
    equation data."""
    parts = as_parts(est)
    spec = choose_filter([p.speed for p in parts], parts[0].sample_rate_hz)
    fb = feedback_z(parts)
    closed = fb > FEEDBACK_Z
    return Setup(spec, kinematic_mode(parts, spec, closed), closed, fb)


def rigid(mass: float, viscous: float, fs: float) -> Plant:
    """The rigid mass-damper sampled at ``fs`` (every effect off)."""
    return Plant(mass_kg=mass, viscous_n_per_mps=max(viscous, 0.0), sample_rate_hz=fs)


def _crude(rec: Parts, su: Setup) -> Plant:
    """Step 1 of the module doc: two-stage least squares through an exactly linear inversion.

    The reference is 1 kg without damping, so the residual is linear in the mass and the
    viscous coefficient. Their regressors (acceleration, speed) are replaced by their
    projection on instruments built from the thrust alone -- the instrumented responses of
    mass-dampers with time constants from five samples to a third of the recording (of its
    longest span when used in spans; one filter memory older under feedback, as
    :mod:`.instruments` builds them; each span's from its own thrust) -- beside a constant,
    sign(v) and the position as exogenous columns.
    """
    parts = as_parts(rec)
    fs = parts[0].sample_rate_hz
    T = 1.0 / fs
    ref = Plant(mass_kg=1.0, viscous_n_per_mps=0.0, sample_rate_hz=fs)
    d = equation_data_parts(ref, parts, su.spec, su.mode, False)
    lag = su.spec.edge if su.closed else 0
    longest = max(len(p) for p in parts)
    taus = np.geomspace(5.0 * T, max(longest * T / 3.0, 50.0 * T), CRUDE_TIME_CONSTANTS)
    bank = np.vstack([
        np.column_stack([c for tau in taus
                         for c in instrumented(p.thrust, T, float(tau), 1.0, su.mode,
                                               d.a_raw[i:j], d.v_raw[i:j], lag)])
        for p, (i, j) in zip(parts, d.instants(), strict=True)])
    exog = d.project(np.column_stack([np.ones(len(d.v)), d.friction(), d.x]))
    Z = np.hstack([d.project(bank), exog])
    endog = d.project(np.column_stack([d.a_raw, d.v_raw]))
    fitted = Z @ np.linalg.lstsq(Z, endog, rcond=None)[0]
    beta, _ = lstsq(np.hstack([fitted, exog]), d.y)
    mass = 1.0 + float(beta[0])
    if not math.isfinite(mass) or mass <= 0:
        mass = 1.0
    viscous = float(beta[1]) if math.isfinite(beta[1]) else 0.0
    return rigid(mass, max(viscous, mass * 1e-3), fs)


def joint_fit(effects: tuple[Effect, ...], data: EquationData) -> Fit:
    """Mass, viscous and ``effects`` estimated together (nonlinear parameters refined)."""
    eff = RIGID + effects
    X, fixed = design(eff, data)
    _, r = lstsq(X, data.y - fixed)
    return refine(eff, data, ar_whitener(r))


def _sd(fit: Fit, k: int) -> float:
    return math.sqrt(max(float(fit.cov[k, k]), 0.0))


def _converge(rec: Parts, su: Setup, ref: Plant, effects: tuple[Effect, ...],
              ) -> tuple[Plant, Fit, EquationData, int]:
    """Step 2/4: move the rigid reference until the mass and viscous steps vanish."""
    parts = as_parts(rec)
    fs = parts[0].sample_rate_hz
    for it in range(1, MAX_ITERATIONS + 1):
        data = equation_data_parts(ref, parts, su.spec, su.mode, su.closed)
        fit = joint_fit(effects, data)
        effects = fit.effects[len(RIGID):]
        dm, db = float(fit.beta[0]), float(fit.beta[1])
        done = abs(dm) <= STEP_TOLERANCE * _sd(fit, 0) and abs(db) <= STEP_TOLERANCE * _sd(fit, 1)
        if done or it == MAX_ITERATIONS:
            return ref, fit, data, it
        mass = ref.mass_kg + dm
        ref = rigid(mass if mass > 0 else 0.5 * ref.mass_kg, ref.viscous_n_per_mps + db, fs)
    raise AssertionError("unreachable")  # pragma: no cover


def fit_physical(rec: Recording | Excerpt, validate: Recording | Excerpt | None = None,
                 opts: FitOptions | None = None) -> PhysicalFit:
    """The whole method of the module doc (``validate``: a held-out recording). A recording
    longer than ``opts.max_samples`` is used in spans spread over it (an :class:`Excerpt`:
    the spans already read)."""
    opts = opts or FitOptions()
    ex = excerpt_for(rec, opts.max_samples, opts.split if validate is None else None)
    held = None if validate is None else excerpt_for(validate, opts.max_samples, None)
    parts = ex.parts
    su = setup(estimation_parts(ex, held, opts.split))
    ref, fit, data, its = _converge(parts, su, _crude(parts, su), START_EFFECTS)
    rounds = 0
    while True:
        rounds += 1
        sel_ref = _reference_of(ref, fit)
        segs = segments(sel_ref, ex, held, opts.split, opts.max_samples)
        ef = fit_effects(sel_ref, segs, opts)
        named_rigid = any(e.name in RIGID_NAMES for e in ef.final.effects)
        effects = tuple(e for e in ef.final.effects if e.name not in RIGID_NAMES)
        ref, fit, data, n = _converge(parts, su, sel_ref, effects)
        its += n
        moved = _moved(sel_ref, ref, fit)
        if rounds >= MAX_ROUNDS or not (moved or named_rigid):
            break
    ref, fit, data, its, dropped = _dissipative(list(parts), su, ref, fit, data, its)
    plant, std, notes = plant_and_std(ref, fit)
    found = _found(ef.found, fit, ref)
    notes += dropped
    final = segments(ref, ex, held, opts.split, opts.max_samples)
    est_joint = joint_fit(fit.effects[len(RIGID):], final.est)
    return PhysicalFit(plant, std, found, ref, fit, data, final, est_joint, ef, su, its,
                       rounds, tuple(notes))


def _dissipative(parts: list[Recording], su: Setup, ref: Plant, fit: Fit, data: EquationData,
                 its: int) -> tuple[Plant, Fit, EquationData, int, list[str]]:
    """Friction takes energy out of the motion: a Stribeck hump beside a Coulomb level of the
    other sign (or of a negative height) is the Coulomb and viscous friction over again
    across the recorded speeds (a hump as wide as the motion is a slope), not a hump. It
    is then left out and the rest fitted again; the note says so."""
    plant, _, _ = plant_and_std(ref, fit)
    cf, sf = plant.coulomb_friction, plant.stribeck_friction
    if sf is None or (sf.static_n >= 0 and (cf is None or cf.amplitude_n >= 0)):
        return ref, fit, data, its, []
    effects = tuple(e for e in fit.effects[len(RIGID):] if e.name != "stribeck_friction")
    ref, fit, data, n = _converge(parts, su, _crude(parts, su), effects)
    coulomb = f", Coulomb {cf.amplitude_n:.3g} N" if cf is not None else ""
    note = (f"a Stribeck hump of {sf.static_n:.3g} N at {sf.velocity_mps * 1e3:.3g} mm/s"
            f"{coulomb} is not dissipative friction: across these speeds it stands for the "
            "Coulomb and viscous friction, and is left out")
    return ref, fit, data, its + n, [note]


def _reference_of(ref: Plant, fit: Fit) -> Plant:
    """The rigid plant with the last mass and viscous steps applied (a step to a mass at or
    below zero is not taken: an unmodelled force in step with the acceleration -- a spring
    under a slow sinusoidal move -- can drive the rigid fit there before it is named)."""
    mass = ref.mass_kg + float(fit.beta[0])
    return rigid(mass if mass > 0 else ref.mass_kg, ref.viscous_n_per_mps + float(fit.beta[1]),
                 ref.sample_rate_hz)


def _moved(before: Plant, ref: Plant, fit: Fit) -> bool:
    """The mass or viscous coefficient moved by more than a standard error."""
    m = ref.mass_kg + float(fit.beta[0])
    b = ref.viscous_n_per_mps + float(fit.beta[1])
    return abs(m - before.mass_kg) > _sd(fit, 0) or abs(b - before.viscous_n_per_mps) > _sd(fit, 1)


def plant_and_std(ref: Plant, fit: Fit) -> tuple[Plant, dict[str, Any], list[str]]:
    """The fitted plant (rigid part plus effect blocks) and its standard errors."""
    mass = ref.mass_kg + float(fit.beta[0])
    viscous = ref.viscous_n_per_mps + float(fit.beta[1])
    notes = []
    if mass <= 0:
        raise PlantError(f"the fitted mass is {mass:.4g} kg: the recording does not identify "
                         "the mass (too little acceleration above the noise)")
    if viscous < 0:
        notes.append(f"the fitted viscous coefficient {viscous:.4g} N s/m is negative; the "
                     "plant holds 0 (within {:.2g} of it)".format(_sd(fit, 1)))
    base = rigid(mass, viscous, ref.sample_rate_hz)
    named = []
    std: dict[str, Any] = {"mass_kg": _sd(fit, 0), "viscous_n_per_mps": _sd(fit, 1)}
    for k in range(len(RIGID), len(fit.effects)):
        params, sd = effect_params(fit, k, base)
        named.append((fit.effects[k].name, params))
        std[fit.effects[k].name] = _block_std(fit, k, sd)
    plant, more = corrected_plant(base, named)
    return plant, std, notes + more


def _block_std(fit: Fit, k: int, sd: dict[str, float]) -> dict[str, Any]:
    """Standard errors of effect k in the plant block's layout (harmonics as a list)."""
    e = fit.effects[k]
    out: dict[str, Any] = {key: v for key, v in sd.items() if not key.startswith("harmonic_")}
    if e.name == "cogging":
        b, cov = fit.beta[fit.slices()[k]], fit.beta_cov(k)
        harm = []
        for j, h in enumerate(e.orders):
            if h == 1:
                continue
            sl = slice(2 * j, 2 * j + 2)
            _, _, sa, sp = _polar(b[sl], cov[sl, sl])
            harm.append({"order": h, "amplitude_n": sa, "phase_rad": sp})
        out["harmonics"] = harm
    return out


def _found(named: tuple[FoundEffect, ...], fit: Fit, ref: Plant) -> tuple[FoundEffect, ...]:
    """The selected effects with parameters and errors from the joint estimate."""
    base = rigid(ref.mass_kg + float(fit.beta[0]), ref.viscous_n_per_mps + float(fit.beta[1]),
                 ref.sample_rate_hz)
    by_name = {fit.effects[k].name: k for k in range(len(RIGID), len(fit.effects))}
    out = []
    for f in named:
        k = by_name.get(f.name)
        if k is None:
            continue
        params, sd = effect_params(fit, k, base)
        out.append(replace(f, params=params, params_std=sd))
    return tuple(out)


__all__ = ["PhysicalFit", "Setup", "check_identifiable", "fit_physical", "joint_fit",
           "plant_and_std", "rigid", "setup"]
