"""Sim-to-real diagnosis: locate the mismatch, name the missing physics, model it, show it.

1. **Locate** -- the equation-error residual of the reference plant
   (:mod:`pmsm_sysid.core.plantfit.kinematics`) is described over time, position, velocity
   and frequency (:mod:`.locate`), and the library's candidates are ranked by ERR on it (the
   position periodogram is the cogging scan).
2. **Name and model** -- the effects the recording shows beyond the plant, selected,
   refined, confirmed on held-out data and re-estimated by the plant-fitting stage
   (:func:`pmsm_sysid.core.plantfit.fit.fit_effects`); the confirmed effects become the
   corrected plant.
3. **What is left** -- the final residual is scanned again; structure no library effect
   explains is modelled as a curve on its axis (:mod:`.nonparam`, :mod:`.local`) and each
   library group is put against such a curve (:mod:`.rival`).
4. **Show** -- NRMSE of the force (equation error) and of a short-horizon speed replay
   (output error, :mod:`.resim`) before/after, on estimation and held-out data, and the
   correlation tests (Eq. 13 of Liu et al. 2005) of the prewhitened residual before/after.

Over frequency the GFRFs of a NARX fitted to the real data and to a noisy simulated twin
are compared too (:mod:`.gfrf_compare`): the H2 ridges and H1 peaks only the real data's
model has are a ``mismatch.where`` entry with ``source: gfrf``.

Held-out data are ``validate`` when given; otherwise the last 30 % of the recording, and
the confirmed effects' parameters are then re-estimated on the whole recording (the fit
table keeps the estimation-only model, so its held-out numbers stay honest).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import DiagnoseError, PmsmSysidError
from ..physics.plant import Plant
from ..plantfit.estimate import Fit, contributions
from ..plantfit.fit import FitOptions, Segments, correct, fit_effects, segments
from ..plantfit.found import FoundEffect, capped
from ..plantfit.translate import effect_params
from ..recording.signals import Recording
from ..recording.spans import Excerpt
from .gfrf_compare import gfrf_where
from .nonparam import AxisModel
from .result import Curves, DiagnoseResult
from .rival import as_found, cap_beside_curves, rivals
from .showfit import beside_curves, fit_table, replay_notes, scan_unexplained, where_table

# the feedback test cannot tell a loop from an open-loop thrust reading's own noise under a
# band-limited input (docs/diagnose.md, step 4): the note names both; either would fake a lag
_CLOSED_NOTE = ("the thrust moves with the measurements' noise (a closed loop, or noise on "
                "the thrust reading: the two look alike): thrust_lag and transport_delay were "
                "not searched -- that noise would fake them")


@dataclass(frozen=True)
class DiagnoseOptions(FitOptions):
    """Thresholds of the method (defaults are the documented ones), and what to show."""

    replay: bool = True
    gfrf: bool = True


def _curves(segs: Segments, fit: Fit, replays: dict[str, Any]) -> Curves:
    from ..plantfit.kinematics import thinned, thinned_times

    c = Curves()
    for name, d in (("estimation", segs.est), ("validation", segs.val)):
        parts = contributions(fit, d)
        c.t[name], c.x[name], c.v[name] = thinned_times(d), thinned(d, d.x), thinned(d, d.v)
        c.before[name] = d.y
        c.after[name] = d.y - (np.sum(parts, axis=0) if parts else 0.0)
        c.parts[name] = [(e.name, p) for e, p in zip(fit.effects, parts, strict=True)]
    c.replay.update(replays)
    return c


def diagnose(plant: Plant, real: Recording | Excerpt, validate: Recording | Excerpt | None = None,
             options: DiagnoseOptions | None = None) -> DiagnoseResult:
    """The whole method of the module doc; raises DiagnoseError on unusable input."""
    opts = options or DiagnoseOptions()
    try:
        return _diagnose(plant, real, validate, opts)
    except PmsmSysidError:
        raise
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise DiagnoseError(f"diagnosis failed on these data: {exc}") from exc


def _diagnose(plant: Plant, real: Recording | Excerpt, validate: Recording | Excerpt | None,
              opts: DiagnoseOptions) -> DiagnoseResult:
    segs = segments(plant, real, validate, opts.split, opts.max_samples)
    closed = segs.closed_loop
    ef = fit_effects(plant, segs, opts)
    model = ef.model
    curves = scan_unexplained(ef.final, ef.data, opts.alpha, opts.min_share,
                              (model.fit, segs.est), segs.val, closed)
    rv = rivals(model.fit, segs.est, segs.val, not closed, opts.alpha)
    curves = beside_curves(curves, [r.model for r in rv], (model.fit, segs.est), segs.val)
    found, _ = cap_beside_curves(ef.found, curves, rv)
    beaten = {r.axis for r in rv}
    unconfirmed = [e for e, _ in curves if e.held_out is not None and not e.held_out.confirmed]
    curves = [(e, m) for e, m in curves if e.held_out is None or e.held_out.confirmed]
    found += [e for e, _ in curves if e.params.get("axis") not in beaten]
    found += [as_found(r) for r in rv]
    extra = _best_curve(curves)
    corrected, notes = correct(plant, [(e.name, e.params) for e in found])
    est_plant, _ = correct(plant, [(e.name, effect_params(model.fit, k, plant)[0])
                                   for k, e in enumerate(model.fit.effects)])
    table, replays = fit_table(plant, est_plant, model.fit, segs, opts.replay, extra)
    notes += replay_notes(table, [e.name for e in model.fit.effects])
    notes += [f"{e.label()} was significant on the estimation data but not confirmed on "
              "held-out data; it is not reported" for e in ef.dropped]
    notes += [f"structure over {e.params['axis']} was significant on the estimation data, "
              "but its curve does not lower the held-out error; it is not reported"
              for e in unconfirmed]
    found, capped_notes = cap_on_replay(found, table)
    notes += capped_notes
    method = _method(segs, opts, ef.n_tests, validate is not None)
    method["feedback"] = {"z": segs.feedback, "closed_loop": closed}
    gfrf = gfrf_where(plant, _middle(segs.pieces("estimation")), opts.alpha) if opts.gfrf \
        else None
    if closed:
        notes.append(_CLOSED_NOTE)
    return DiagnoseResult(
        plant=plant, corrected=corrected, effects=tuple(found),
        where=tuple(where_table(segs.est, list(ef.ranking))), nrmse_before=table["estimation"]
        ["nrmse_before"], fit=table, candidates=tuple(_rank_dict(s) for s in ef.ranking),
        method=method, notes=tuple(notes), curves=_curves(segs, model.fit, replays),
        gfrf=gfrf)


def cap_on_replay(found: list[FoundEffect], table: dict[str, Any],
                  ) -> tuple[list[FoundEffect], list[str]]:
    """No 'high' when the held-out recording, replayed through the corrected plant, comes
    out significantly worse: 'high' needs the held-out data to agree at plant level too."""
    oe = (table.get("validation") or {}).get("output_error")
    if not oe or oe.get("verdict") != "worse":
        return found, []
    out, lowered = [], []
    for e in found:
        if e.confidence == "high":
            lowered.append(e.name)
            e = replace(e, confidence="moderate", notes=(*e.notes, (
                "the corrected plant replays the held-out recording worse")))
        out.append(e)
    note = (f"{', '.join(lowered)}: confidence lowered to moderate -- the held-out "
            "recording replays worse with the correction" if lowered else "")
    return out, [note] if note else []


def _best_curve(curves: list[tuple[FoundEffect, AxisModel]]) -> AxisModel | None:
    """The confirmed unexplained curve that lowers the held-out error most (for the fit)."""
    ok = [(e.held_out.reduction, m) for e, m in curves
          if e.held_out is not None and e.held_out.significant]
    return max(ok, key=lambda t: t[0])[1] if ok else None


def _middle(parts: tuple[Recording, ...]) -> Recording:
    """The central part (the GFRF comparison fits a NARX to one contiguous window)."""
    return parts[len(parts) // 2]


def _rank_dict(s: Any) -> dict[str, Any]:
    return {"candidate": s.effect.label(), "name": s.effect.name, "err": s.err,
            "share": s.share, "significance": capped(-s.significance)}


def _method(segs: Segments, opts: DiagnoseOptions, n_tests: float,
            has_validate: bool) -> dict[str, Any]:
    return {
        "residual": "equation error (inverse dynamics), parallel-filtered",
        "speed_source": "measured" if segs.est.mode == "speed" else "derived from position",
        "filter": segs.est.filt.to_dict(),
        "regression_samples": {"estimation": segs.est.n, "validation": segs.val.n},
        "held_out": "--validate recording" if has_validate
        else f"last {1 - opts.split:.0%} of the recording",
        "parameters_from": "estimation recording" if has_validate else "whole recording",
        "alpha": opts.alpha, "min_share": opts.min_share, "tests_searched": n_tests,
        "significance": "-log10 of the Bonferroni-corrected p-value (prewhitened F-test)",
        "sign_smoothing_mps": segs.est.sign_smoothing_mps,
        "data_used": segs.used, "max_samples": opts.max_samples,
        "thrust_reading": {"noise_n": segs.thrust_noise_n,
                           "gap_samples": segs.est.thrust_gap},
    }


__all__ = ["DiagnoseOptions", "DiagnoseResult", "diagnose"]
