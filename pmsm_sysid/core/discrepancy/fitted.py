"""A plant fitted from a recording, and what a plant file cannot hold.

:func:`fit_plant` runs the physical fit (:mod:`pmsm_sysid.core.plantfit.physical`: mass and
viscous damping always, the library's effects by selection) and then judges the recording
against its own fitted plant as ``diagnose`` judges it against a given one: structure left
in the residual that no library effect explains is modelled as a curve on its axis
(:func:`.showfit.scan_unexplained`) and reported as ``unexplained`` -- never written into
the plant file, which has no block for it; the thrust axis is scanned in either loop, for a
bend beyond a straight line over thrust (:func:`leftover`). Each library group is also put
against a curve on its axis (:func:`.rival.rivals`; the mass and viscous terms are the
plant's own and are never replaced): when a curve predicts the held-out data better, or a
confirmed curve explains what is left on an effect's axis, that effect is not 'high' (as in
``diagnose``) -- and when that axis is the thrust or the speed, neither are the mass and
viscous damping (:attr:`PlantFitResult.rigid_capped`). The fit table is the force (equation-error)
NRMSE of the rigid part alone (mass and viscous damping) and of the whole fitted plant, on
the estimation data and on held-out data, both with the parameters estimated on the
estimation data only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import DiagnoseError, PmsmSysidError
from ..physics.plant import Plant, plant_to_dict
from ..plantfit.estimate import contributions
from ..plantfit.fit import FitOptions
from ..plantfit.found import FoundEffect, effect_line
from ..plantfit.physical import PhysicalFit, fit_physical
from ..plantfit.stats import nrmse
from ..recording.signals import Recording
from ..recording.spans import Excerpt
from .nonparam import AxisModel
from .rival import as_found, cap_beside_curves, rivals
from .showfit import scan_unexplained
from .words import unexplained_text, used_lines

RIGID_NAMES = ("mass_error", "viscous_error")


@dataclass(frozen=True)
class PlantFitResult:
    """The fitted plant, its standard errors, the effects found and what is left."""

    physical: PhysicalFit
    effects: tuple[FoundEffect, ...]
    """The library effects of the plant, then any ``unexplained`` structure (not in it)."""
    fit: dict[str, Any]
    method: dict[str, Any]
    notes: tuple[str, ...] = ()
    curves: tuple[tuple[FoundEffect, AxisModel], ...] = ()
    """The ``unexplained`` entries with their curves (confirmed on held-out data)."""
    rigid_capped: bool = False
    """A curve over thrust or speed explains held-out data better than, or beside, the
    rigid part: the mass and viscous damping are not the whole story there."""

    @property
    def plant(self) -> Plant:
        return self.physical.plant

    @property
    def std(self) -> dict[str, Any]:
        return self.physical.std

    def plant_dict(self) -> dict[str, Any]:
        """The plant-file keys of the fitted plant."""
        return plant_to_dict(self.plant)

    def to_dict(self) -> dict[str, Any]:
        return {"plant": self.plant_dict(), "std": self.std,
                "effects": [e.to_dict() for e in self.effects], "fit": self.fit,
                "method": self.method, "notes": list(self.notes)}

    def summary(self) -> str:
        """Lines for people: mass and viscous ± standard error, effects, fit, notes."""
        p, s = self.plant, self.std
        lines = used_lines(self.method)
        lines += [f"  mass_kg = {p.mass_kg:.5g} ± {s['mass_kg']:.2g}",
                 f"  viscous_n_per_mps = {p.viscous_n_per_mps:.5g} ± "
                 f"{s['viscous_n_per_mps']:.2g}"]
        if not self.effects:
            lines.append("  no library effect beyond the mass and viscous damping")
        for e in self.effects:  # an unexplained force in words, as diagnose says it
            lines.append(effect_line(e, unexplained_text(e.params)
                                     if e.name == "unexplained" else None))
            lines += [f"    note: {n}" for n in e.notes]
        for seg in ("estimation", "validation"):
            f = self.fit.get(seg)
            if f:
                lines.append(f"{seg}: force NRMSE {f['nrmse_before']:.4f} (mass and viscous "
                             f"only) -> {f['nrmse_after']:.4f} (fitted plant)")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def fit_plant(rec: Recording | Excerpt, validate: Recording | Excerpt | None = None,
              opts: FitOptions | None = None) -> PlantFitResult:
    """The module doc's method; raises :class:`DiagnoseError` on unusable input."""
    opts = opts or FitOptions()
    try:
        pf = fit_physical(rec, validate, opts)
        curves = leftover(pf, opts)
        rv = rivals(pf.est_joint, pf.segs.est, pf.segs.val, not pf.setup.closed, opts.alpha,
                    never=RIGID_NAMES)
    except PmsmSysidError:
        raise
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise DiagnoseError(f"fitting a plant failed on these data: {exc}") from exc
    found, near = cap_beside_curves(pf.found, curves, rv)
    beaten = {r.axis for r in rv}
    curves = [(e, m) for e, m in curves if e.params.get("axis") not in beaten]
    curves += [(as_found(r), r.model) for r in rv]
    notes = list(pf.notes)
    if curves:
        notes.append("unexplained structure is reported, not written into the plant file "
                     "(a plant file has no block for it)")
    pf = replace(pf, found=tuple(found))
    return PlantFitResult(pf, pf.found + tuple(e for e, _ in curves), fit_rows(pf),
                          method(pf, opts, validate is not None), tuple(notes),
                          tuple(curves), bool(near & set(RIGID_NAMES)))


def leftover(pf: PhysicalFit, opts: FitOptions) -> list[tuple[FoundEffect, AxisModel]]:
    """``unexplained`` entries (with their curves) for structure the fitted plant leaves in
    its residual, confirmed on held-out data (a curve that does not lower the held-out
    error is dropped). The thrust axis is scanned in either loop, against a straight line
    over thrust as ``diagnose`` scans it under feedback: a fitted plant's rigid part takes
    up what it can of a force over thrust (an actuator dead zone made the mass 10 % and
    the damping 15 % larger), and a noisy thrust reading makes the residual lean on the
    thrust in a straight line -- only a bend beyond it is the plant's. Open loop a noisy
    reading of a bounded thrust (a chirp's or a sine's crests) bends the lean at the ends
    of the range too: there the curve is judged beyond the line and that bend
    (:func:`.nonparam.noise_lean`), and must lower the held-out error significantly."""
    curves = scan_unexplained(pf.joint, pf.data, opts.alpha, opts.min_share,
                              (pf.est_joint, pf.segs.est), pf.segs.val, True,
                              lean=not pf.setup.closed)
    return [(e, m) for e, m in curves if e.held_out is None or (
        e.held_out.significant if m.axis == "thrust" and not pf.setup.closed
        else e.held_out.confirmed)]


def fit_rows(pf: PhysicalFit) -> dict[str, Any]:
    """Force NRMSE of the rigid part and of the whole plant, estimated on the estimation
    data, on estimation and held-out data."""
    out: dict[str, Any] = {}
    for name, d in (("estimation", pf.segs.est), ("validation", pf.segs.val)):
        parts = contributions(pf.est_joint, d)
        target = d.project(d.force)
        rigid_only = d.y - parts[0] - parts[1]
        after = d.y - np.sum(parts, axis=0)
        out[name] = {"nrmse_before": nrmse(target, rigid_only), "nrmse_after":
                     nrmse(target, after), "samples": d.n,
                     "before": "mass and viscous damping only", "after": "the fitted plant"}
    return out


def method(pf: PhysicalFit, opts: FitOptions, has_validate: bool) -> dict[str, Any]:
    """How the plant was fitted (filter, loop, held-out data, iterations, thresholds)."""
    d = pf.segs.est
    return {
        "residual": "equation error (inverse dynamics), parallel-filtered",
        "mass_and_viscous": "always estimated, instrumental variables (IDIM-IV), iterated "
                            "until the reference plant settles",
        "speed_source": "measured" if d.mode == "speed" else "derived from position",
        "filter": d.filt.to_dict(),
        "feedback": {"z": pf.setup.feedback, "closed_loop": pf.setup.closed},
        "regression_samples": {"estimation": d.n, "validation": pf.segs.val.n},
        "held_out": "--validate recording" if has_validate
        else f"last {1 - opts.split:.0%} of the recording",
        "parameters_from": "estimation recording" if has_validate else "whole recording",
        "iterations": pf.iterations, "selection_rounds": pf.rounds,
        "alpha": opts.alpha, "min_share": opts.min_share,
        "sample_rate_hz": 1.0 / d.period,
        "data_used": pf.segs.used, "max_samples": opts.max_samples,
    }


__all__ = ["PlantFitResult", "fit_plant", "fit_rows", "leftover", "method"]
