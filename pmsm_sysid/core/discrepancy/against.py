"""A recording against a recording: the user's simulator against the real drive.

The simulator is known only through a recording of it, so its plant is fitted first
(:func:`.fitted.fit_plant`: mass, viscous damping and the library's effects, with standard
errors); the real recording's plant is fitted the same way. The two recordings need not
share anything but the axis: excitation, length, sample rate, loop, noise and topic layout
may all differ, since each plant is identified from its own data in SI units.

1. **Changes** (:mod:`.changes`): every parameter is compared against the combined
   standard error of both fits; an effect only one side has is compared with what the
   other recording says about it. Bonferroni over every test made.
2. **Effects** (:mod:`.sidebyside`): the changes grouped by effect -- ``effects`` is what
   the real drive has beyond the simulation (as ``diagnose`` against a plant file reports
   it), ``sim_only`` what the simulation has that the real drive lacks; structure no
   library effect explains goes to the side that shows it when the other does not show it
   on the same axis.
3. **Corrected plant**: the simulation's fitted plant with the changes applied.
4. **Show**: the simulation's plant and the corrected plant judged on the real recording --
   force (equation-error) NRMSE and the short-horizon speed replay on estimation and
   held-out data, the corrected plant built with the real parameters estimated on the
   estimation part only, so the held-out numbers stay honest. Where the mismatch lives
   (:mod:`.locate`) and the GFRF comparison are those of the simulation's plant on the real
   recording. A held-out fit that does not improve takes every 'high' away.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import DiagnoseError, PmsmSysidError
from ..physics.plant import Plant
from ..plantfit.found import FoundEffect
from ..plantfit.kinematics import EquationData, thinned, thinned_times
from ..plantfit.parts import equation_data_parts
from ..plantfit.physical import PhysicalFit, plant_and_std
from ..plantfit.stats import HeldOutTest, held_out_test, nrmse
from ..recording.signals import Recording
from ..recording.spans import Excerpt
from .changes import Change, compare, found_by_name
from .diagnose import DiagnoseOptions, cap_on_replay
from .fitted import PlantFitResult, fit_plant
from .gfrf_compare import gfrf_where
from .resim import choose_horizon
from .resim import compare as replay_compare
from .result import Curves, DiagnoseResult
from .showfit import replay_notes, where_table
from .sidebyside import SimComparison, apply_changes, beyond_sim, groups, sim_only

SEGMENTS = ("estimation", "validation")


def diagnose_sim(sim: Recording | Excerpt, real: Recording | Excerpt,
                 validate: Recording | Excerpt | None = None,
                 options: DiagnoseOptions | None = None) -> DiagnoseResult:
    """The module doc's method; raises DiagnoseError on unusable input."""
    opts = options or DiagnoseOptions()
    try:
        return _against(sim, real, validate, opts)
    except PmsmSysidError:
        raise
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise DiagnoseError(f"diagnosis failed on these data: {exc}") from exc


def _against(sim_rec: Recording | Excerpt, real_rec: Recording | Excerpt,
             validate: Recording | Excerpt | None, opts: DiagnoseOptions) -> DiagnoseResult:
    sim = fit_plant(sim_rec, None, opts)
    real = fit_plant(real_rec, validate, opts)
    rows, notes, n_tests = compare(sim.physical, real.physical, opts.alpha)
    real_est = plant_and_std(real.physical.reference, real.physical.est_joint)[0]
    before = {s: _data(sim.plant, real.physical, s) for s in SEGMENTS}
    judged = _judge(rows, sim.plant, real_est, real.physical, before)
    rows = judged.rows
    corrected_est = apply_changes(sim.plant, real_est, rows)
    after = {s: _data(corrected_est, real.physical, s) for s in SEGMENTS}
    table, replays = _table(sim.plant, corrected_est, before, after, real.physical, opts)
    rows, capped = _cap(rows, table)
    effects = beyond_sim(rows, sim.plant, real.plant, found_by_name(real.physical),
                         judged.held, judged.shares)
    only = sim_only(rows, found_by_name(sim.physical), judged.held, judged.shares, sim.plant)
    more, less, left_notes = _unexplained(sim, real)
    found, replay_capped = cap_on_replay(effects + more, table)
    notes += judged.notes + capped + replay_capped + left_notes
    notes += replay_notes(table, list(groups(rows)))
    notes += [f"simulation's recording: {n}" for n in sim.notes]
    notes += [f"real recording: {n}" for n in real.notes]
    pieces = real.physical.segs.pieces("estimation")
    gfrf = gfrf_where(sim.plant, pieces[len(pieces) // 2], opts.alpha) if opts.gfrf else None
    comparison = SimComparison(sim, real, tuple(rows), tuple(only + less), n_tests)
    return DiagnoseResult(
        plant=sim.plant, corrected=apply_changes(sim.plant, real.plant, rows),
        effects=tuple(found), where=tuple(where_table(before["estimation"], [])),
        nrmse_before=table["estimation"]["nrmse_before"], fit=table, candidates=(),
        method=_method(sim, real, n_tests, opts, validate is not None),
        notes=tuple(notes), curves=_curves(before, after, judged.parts, replays), gfrf=gfrf,
        against=comparison)


def _data(plant: Plant, pf: PhysicalFit, segment: str) -> EquationData:
    """``plant``'s equation data on a segment of the real recording, built as the real
    fit built its own (same filter, kinematic mode and loop)."""
    d = pf.segs.est if segment == "estimation" else pf.segs.val
    return equation_data_parts(plant, pf.segs.pieces(segment), d.filt, d.mode,
                               pf.setup.closed)


def _table(sim_plant: Plant, corrected: Plant, before: dict[str, EquationData],
           after: dict[str, EquationData], pf: PhysicalFit, opts: DiagnoseOptions,
           ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Force NRMSE before/after on both segments, and the speed replay when asked."""
    table: dict[str, Any] = {}
    replays: dict[str, dict[str, Any]] = {}
    def sizes(seg: str) -> tuple[int, ...]:
        pieces = pf.segs.pieces(seg)
        return tuple(len(p) for p in pieces) if len(pieces) > 1 else ()

    horizon = choose_horizon((sim_plant, corrected), pf.segs.recs["estimation"],
                             parts=sizes("estimation")) if opts.replay else None
    for seg in SEGMENTS:
        b, a = before[seg], after[seg]
        target = b.project(b.force)
        row: dict[str, Any] = {"nrmse_before": nrmse(target, b.y),
                               "nrmse_after": nrmse(target, a.y), "samples": b.n}
        if horizon is not None:
            rec = pf.segs.recs[seg]
            cmp = replay_compare(sim_plant, corrected, rec, horizon, sizes(seg))
            row["output_error"] = cmp.to_dict()
            replays[seg] = {"t": rec.t, "measured": rec.speed, "before": cmp.before.speed,
                            "after": cmp.after.speed}
        table[seg] = row
    return table, replays


def _cap(rows: list[Change], table: dict[str, Any]) -> tuple[list[Change], list[str]]:
    """No 'high' change when the corrected plant does not fit the held-out data better."""
    val = table["validation"]
    if not rows or val["nrmse_after"] < val["nrmse_before"]:
        return rows, []
    out = [replace(r, confidence="moderate") if r.confidence == "high" else r for r in rows]
    note = ("the corrected plant does not fit the held-out real data better than the "
            "simulation's plant: no change is 'high'") if out != rows else ""
    return out, [note] if note else []


@dataclass(frozen=True)
class Judged:
    """The changes that the real recording's held-out data confirm, effect by effect."""

    rows: list[Change]
    held: dict[str, HeldOutTest]
    """Per effect: the held-out test of its changes on the real data."""
    shares: dict[str, float]
    parts: dict[str, list[tuple[str, Any]]]
    notes: list[str]


def _judge(rows: list[Change], sim_plant: Plant, real_est: Plant, pf: PhysicalFit,
           before: dict[str, EquationData]) -> Judged:
    """Each effect's changes judged on held-out real data, as ``diagnose`` judges effects:
    the simulation's plant with every change applied (real values estimated on the
    estimation part) against the same without this effect's changes (Diebold-Mariano on
    the force error). The weakest effect that does not lower the held-out error is
    dropped and the rest judged again; one that lowers it by no more than chance would is
    'low', 'high' needs p < 0.001. Its share of the mismatch is that of its changes alone."""
    notes: list[str] = []
    kept = list(rows)
    while True:
        by = groups(kept)
        y_all = {s: _data(apply_changes(sim_plant, real_est, kept), pf, s).y for s in SEGMENTS}
        minus = {n: {s: _data(apply_changes(sim_plant, real_est, [r for r in kept
                                                                  if r.effect != n]), pf, s).y
                     for s in SEGMENTS} for n in by}
        tests = {n: held_out_test(minus[n]["validation"], y_all["validation"]) for n in by}
        failing = [(t.z, n) for n, t in tests.items() if not t.confirmed]
        if not failing:
            break
        _, worst = min(failing)
        notes.append(f"{worst}: the change does not lower the force error on held-out real "
                     f"data (mean-square error {-tests[worst].reduction:+.0%}); it is not "
                     "reported")
        kept = [r for r in kept if r.effect != worst]
    e0 = float(before["estimation"].y @ before["estimation"].y)
    shares = {}
    for n, rs in by.items():
        y = _data(apply_changes(sim_plant, real_est, rs), pf, "estimation").y
        shares[n] = max(0.0, 1.0 - float(y @ y) / e0) if e0 > 0 else 0.0
    parts = {s: [(n, minus[n][s] - y_all[s]) for n in by] for s in SEGMENTS}
    kept = [replace(r, confidence=_held_confidence(r.confidence, tests[r.effect].p_value))
            for r in kept]
    return Judged(kept, tests, shares, parts, notes)


def _held_confidence(confidence: str, p_value: float) -> str:
    if p_value >= 0.05:
        return "low"
    if confidence == "high" and p_value >= 1e-3:
        return "moderate"
    return confidence


def _unexplained(sim: PlantFitResult, real: PlantFitResult,
                 ) -> tuple[list[FoundEffect], list[FoundEffect], list[str]]:
    """Unexplained structure on an axis only one recording shows goes to that side."""
    def axes(f: PlantFitResult) -> dict[str, FoundEffect]:
        return {str(e.params.get("axis")): e for e in f.effects if e.name == "unexplained"}

    s_ax, r_ax = axes(sim), axes(real)
    notes = [f"both recordings show structure over {a} that no library effect explains; "
             "it is not compared" for a in r_ax if a in s_ax]
    return ([e for a, e in r_ax.items() if a not in s_ax],
            [e for a, e in s_ax.items() if a not in r_ax], notes)


def _method(sim: PlantFitResult, real: PlantFitResult, n_tests: int, opts: DiagnoseOptions,
            has_validate: bool) -> dict[str, Any]:
    m = dict(real.method)
    m.update(reference="simulator's recording: its plant fitted (mass, viscous, effects)",
             held_out="--validate recording" if has_validate
             else f"last {1 - opts.split:.0%} of the real recording",
             comparison={"statistic": "difference over the combined standard error of both "
                                      "fitted plants (an effect one side lacks: against the "
                                      "other recording's cross-estimate)",
                         "tests": n_tests, "correction": "Bonferroni over the tests",
                         "alpha": opts.alpha},
             sim=sim.method)
    m["significance"] = "-log10 of the Bonferroni-corrected p-value"
    return m


def _curves(before: dict[str, EquationData], after: dict[str, EquationData],
            parts: dict[str, list[tuple[str, Any]]],
            replays: dict[str, dict[str, Any]]) -> Curves:
    c = Curves()
    for seg in SEGMENTS:
        d = before[seg]
        c.t[seg], c.x[seg], c.v[seg] = thinned_times(d), thinned(d, d.x), thinned(d, d.v)
        c.before[seg], c.after[seg] = d.y, after[seg].y
        c.parts[seg] = parts[seg]
    c.replay.update(replays)
    return c


__all__ = ["diagnose_sim"]
