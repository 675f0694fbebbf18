"""Is a library name the best explanation? Its rival: a curve on the same axis.

A force the library does not have (a bump at one place of the stroke, an actuator dead
zone) is partly absorbed by library effects that share its axis (a cogging term and an
offset; a mass and a viscous change). Each such group is put against a smooth curve on its
axis (:mod:`.nonparam`; friction terms against a friction curve over position) that
replaces it, both fitted on the estimation data with the other
effects; if the curve predicts the held-out data significantly better, the library group
was not the best explanation: its confidence is capped and the curve is reported as
``unexplained``, with where it lives. A tie keeps the library name -- unless the group
holds a cogging or ripple whose pitch the travel does not cover twice (not identified as
periodic, :func:`.library.periods_seen`): then the library must predict the held-out data
significantly better than the curve to keep the axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..plantfit.estimate import Fit, contributions, design, remainder_of
from ..plantfit.found import FoundEffect
from ..plantfit.kinematics import EquationData
from ..plantfit.library import MIN_PERIODS, periods_seen
from ..plantfit.select import share_of
from ..plantfit.stats import HeldOutTest, held_out_test, nested_f_test
from .nonparam import AxisModel, fit_axis_with

FloatArray = NDArray[np.float64]

# the library effects whose force lives on each axis
AXIS_EFFECTS = {
    "position": ("cogging", "thrust_ripple", "spring", "force_offset"),
    "position_friction": ("coulomb_friction", "stribeck_friction"),
    "velocity": ("coulomb_friction", "stribeck_friction", "viscous_error"),
    "thrust": ("mass_error", "viscous_error", "thrust_lag", "transport_delay",
               "coulomb_friction", "stribeck_friction", "force_offset"),
    "time": ("force_offset",),
}


@dataclass(frozen=True)
class Rival:
    """A curve that beat the library effects ``replaced`` on held-out data."""

    axis: str
    model: AxisModel
    held: HeldOutTest
    replaced: tuple[str, ...]
    significance: float
    share: float


def _fit(fit: Fit, keep: tuple[int, ...], est: EquationData, val: EquationData,
         kind: str) -> tuple[AxisModel, float, FloatArray, float]:
    """Curve ``kind`` with the effects ``keep``: model, est SSE, held-out error, -log10 p."""
    rest = tuple(fit.effects[k] for k in keep)
    X, fixed = design(rest, est)
    y = est.y - fixed - remainder_of(fit, est, keep)
    model, beta, sse = fit_axis_with(est, y, X, kind)
    Xv, fv = design(rest, val)
    err = val.y - fv - remainder_of(fit, val, keep) - (Xv @ beta if Xv.shape[1] else 0.0) \
        - model.force(val)
    cols = model.projected(est)
    test = nested_f_test(y, X, cols, null_whitening=True)
    return model, sse, err, -test.corrected_log10_p(4.0)


def rivals(fit: Fit, est: EquationData, val: EquationData, thrust: bool,
           alpha: float, never: tuple[str, ...] = ()) -> list[Rival]:
    """Curves that explain held-out data better than the library group on their axis
    (``never``: effects never replaced -- a fitted plant's own mass and viscous terms)."""
    parts = contributions(fit, val)
    e_lib = val.y - (np.sum(parts, axis=0) if parts else 0.0)
    out = []
    for kind in ("position", "position_friction", "velocity", "thrust"):
        if kind == "thrust" and not thrust:
            continue
        group = [k for k, e in enumerate(fit.effects)
                 if e.name in AXIS_EFFECTS[kind] and e.name not in never]
        if not group:
            continue
        keep = tuple(k for k in range(len(fit.effects)) if k not in group)
        best = _fit(fit, keep, est, val, kind)
        held = held_out_test(e_lib, best[2])
        axis = kind.split("_")[0]
        unidentified = any(periods_seen(fit.effects[k], est) < MIN_PERIODS for k in group)
        wins = held.significant or (unidentified and held.z > 0.0
                                    and not held_out_test(best[2], e_lib).significant)
        if wins and best[3] > -math.log10(alpha):
            rest = tuple(fit.effects[k] for k in keep)
            X, fixed = design(rest, est)
            share = share_of(est.y - fixed - remainder_of(fit, est, keep), X,
                             best[0].projected(est))
            out.append(Rival(axis, best[0], held,
                             tuple(fit.effects[k].name for k in group), best[3], share))
    best_of: dict[str, Rival] = {}
    for r in out:  # one curve per axis: the one that predicts the held-out data best
        if r.axis not in best_of or r.held.reduction > best_of[r.axis].held.reduction:
            best_of[r.axis] = r
    return list(best_of.values())


def as_found(r: Rival) -> FoundEffect:
    """The rival curve as an ``unexplained`` entry."""
    return FoundEffect(
        "unexplained", {"axis": r.axis, **r.model.describe()}, {}, r.significance, r.share,
        r.held, "moderate" if r.held.significant else "low",
        (f"a curve over {r.axis} predicts held-out data better than "
         f"{', '.join(r.replaced)} (held-out MSE -{r.held.reduction:.0%}, z={r.held.z:.1f})",))


def cap_beside_curves(found: list[FoundEffect] | tuple[FoundEffect, ...],
                      curves: list[tuple[FoundEffect, AxisModel]],
                      rv: list[Rival]) -> tuple[list[FoundEffect], set[str]]:
    """No 'high' for a library effect when a curve confirmed on held-out data explains what
    is left on its axis, or a rival curve explains it better than the effect: the library
    was not the best explanation there. Returns the effects and every library name so
    capped (``diagnose`` and ``fit-plant`` alike)."""
    axes = {m.axis for e, m in curves if e.held_out is not None and e.held_out.significant}
    near = {n for a in axes for n in AXIS_EFFECTS.get(a, ())}
    near |= {n for r in rv for n in r.replaced}
    out = []
    for e in found:
        if e.name in near and e.confidence == "high":
            e = replace(e, confidence="moderate", notes=(*e.notes, (
                "an unexplained force remains on its axis and a curve explains held-out "
                "data better than this effect alone: it is part of the story at most")))
        out.append(e)
    return out, near
