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
from numpy.typing import NDArray

from ..errors import DiagnoseError, PmsmSysidError
from ..physics.plant import Plant
from ..plantfit.found import FoundEffect
from ..plantfit.kinematics import EquationData, thinned, thinned_times
from ..plantfit.library import Effect, columns
from ..plantfit.parts import equation_data_parts
from ..plantfit.physical import PhysicalFit, plant_and_std
from ..plantfit.stats import HeldOutTest, held_out_test, nrmse
from ..recording.signals import Recording
from ..recording.spans import Excerpt
from .changes import RIGID_PARAMS, Change, compare, found_by_name
from .diagnose import DiagnoseOptions, cap_on_replay
from .fitted import PlantFitResult, fit_plant
from .gfrf_compare import gfrf_where
from .nonparam import AxisModel
from .resim import choose_horizon
from .resim import compare as replay_compare
from .result import Curves, DiagnoseResult
from .showfit import replay_notes, where_table
from .sidebyside import SimComparison, apply_changes, beyond_sim, groups, sim_only

SEGMENTS = ("estimation", "validation")
FloatArray = NDArray[np.float64]


def diagnose_sim(sim: Recording | Excerpt, real: Recording | Excerpt,
                 validate: Recording | Excerpt | None = None,
                 options: DiagnoseOptions | None = None,
                 sim_fit: PlantFitResult | None = None) -> DiagnoseResult:
    """The module doc's method; raises DiagnoseError on unusable input. ``sim_fit``: the
    simulator's recording already fitted (:func:`.fitted.fit_plant` with the same options),
    so that many real recordings diagnosed against one simulation fit it once."""
    opts = options or DiagnoseOptions()
    try:
        return _against(sim, real, validate, opts, sim_fit)
    except PmsmSysidError:
        raise
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise DiagnoseError(f"diagnosis failed on these data: {exc}") from exc


def _against(sim_rec: Recording | Excerpt, real_rec: Recording | Excerpt,
             validate: Recording | Excerpt | None, opts: DiagnoseOptions,
             sim_fit: PlantFitResult | None = None) -> DiagnoseResult:
    sim = sim_fit if sim_fit is not None else fit_plant(sim_rec, None, opts)
    real = fit_plant(real_rec, validate, opts)
    rows, notes, n_tests = compare(sim.physical, real.physical, opts.alpha)
    rows, notes = _rigid_cap(rows, sim, real), notes + _rigid_note(rows, sim, real)
    real_est = plant_and_std(real.physical.reference, real.physical.est_joint)[0]
    res = Residuals(sim.plant, real.physical)
    judged = _judge(rows, real_est, res)
    rows = judged.rows
    more, less, left_notes = _unexplained(sim, real)
    corrected_est = apply_changes(sim.plant, real_est, rows)
    table, replays, after = _table(corrected_est, res, opts, _best_curve(more))
    rows, capped = _cap(rows, table)
    effects = beyond_sim(rows, sim.plant, real.plant, found_by_name(real.physical),
                         judged.held, judged.shares)
    only = sim_only(rows, found_by_name(sim.physical), judged.held, judged.shares, sim.plant)
    found, replay_capped = cap_on_replay(effects + [e for e, _ in more], table)
    notes += judged.notes + capped + replay_capped + left_notes
    notes += replay_notes(table, list(groups(rows)))
    notes += [f"simulation's recording: {n}" for n in sim.notes]
    notes += [f"real recording: {n}" for n in real.notes]
    pieces = real.physical.segs.pieces("estimation")
    gfrf = gfrf_where(sim.plant, pieces[len(pieces) // 2], opts.alpha) if opts.gfrf else None
    comparison = SimComparison(sim, real, tuple(rows), tuple(only + [e for e, _ in less]),
                               n_tests)
    return DiagnoseResult(
        plant=sim.plant, corrected=apply_changes(sim.plant, real.plant, rows),
        effects=tuple(found), where=tuple(where_table(res.before["estimation"], [])),
        nrmse_before=table["estimation"]["nrmse_before"], fit=table, candidates=(),
        method=_method(sim, real, n_tests, opts, validate is not None),
        notes=tuple(notes), curves=_curves(res.before, after, judged.parts, replays),
        gfrf=gfrf,
        against=comparison)


def _data(plant: Plant, pf: PhysicalFit, segment: str) -> EquationData:
    """``plant``'s equation data on a segment of the real recording, built as the real
    fit built its own (same filter, kinematic mode and loop)."""
    d = pf.segs.est if segment == "estimation" else pf.segs.val
    return equation_data_parts(plant, pf.segs.pieces(segment), d.filt, d.mode,
                               pf.setup.closed, d.thrust_gap)


class Residuals:
    """Force residuals of the simulation's plant, changed or not, on the real recording.

    A changed mass or viscous coefficient enters through the instrumented columns of the
    simulation plant's equation data (as ``diagnose``'s mass and viscous errors do): the
    measured acceleration and speed carry the sensors' noise, and an equation error
    rebuilt with another mass carries that much more of it -- on a noisy speed the true
    mass gave a larger residual than a wrong one. Changed effects are rebuilt exactly.
    """

    def __init__(self, sim_plant: Plant, pf: PhysicalFit) -> None:
        self.sim, self.pf = sim_plant, pf
        self.before = {s: _data(sim_plant, pf, s) for s in SEGMENTS}
        self._rigid = {s: (columns(Effect("mass_error"), d)[:, 0],
                           columns(Effect("viscous_error"), d)[:, 0])
                       for s, d in self.before.items()}

    def __call__(self, plant: Plant, segment: str) -> FloatArray:
        """The residual of ``plant`` (the simulation's with some changes) on ``segment``."""
        same = replace(plant, mass_kg=self.sim.mass_kg,
                       viscous_n_per_mps=self.sim.viscous_n_per_mps)
        y = self.before[segment].y if same == self.sim else _data(same, self.pf, segment).y
        a, v = self._rigid[segment]
        out: FloatArray = y - (plant.mass_kg - self.sim.mass_kg) * a \
            - (plant.viscous_n_per_mps - self.sim.viscous_n_per_mps) * v
        return out


def _table(corrected: Plant, res: Residuals, opts: DiagnoseOptions,
           extra: AxisModel | None = None,
           ) -> tuple[dict[str, Any], dict[str, dict[str, Any]], dict[str, FloatArray]]:
    """Force NRMSE before/after on both segments (after: the corrected plant, with the
    real recording's best confirmed unexplained curve, as ``diagnose`` shows it), the
    speed replay when asked, and the residuals after."""
    table: dict[str, Any] = {}
    replays: dict[str, dict[str, Any]] = {}
    after: dict[str, FloatArray] = {}
    recs = res.pf.segs.recs

    def sizes(seg: str) -> tuple[int, ...]:
        pieces = res.pf.segs.pieces(seg)
        return tuple(len(p) for p in pieces) if len(pieces) > 1 else ()

    horizon = choose_horizon((res.sim, corrected), recs["estimation"],
                             parts=sizes("estimation")) if opts.replay else None
    for seg in SEGMENTS:
        b = res.before[seg]
        target = b.project(b.force)
        after[seg] = res(corrected, seg) - (extra.force(b) if extra is not None else 0.0)
        row: dict[str, Any] = {"nrmse_before": nrmse(target, b.y),
                               "nrmse_after": nrmse(target, after[seg]), "samples": b.n}
        if horizon is not None:
            cmp = replay_compare(res.sim, corrected, recs[seg], horizon, sizes(seg))
            row["output_error"] = cmp.to_dict()
            replays[seg] = {"t": recs[seg].t, "measured": recs[seg].speed,
                            "before": cmp.before.speed, "after": cmp.after.speed}
        table[seg] = row
    return table, replays, after


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


def _judge(rows: list[Change], real_est: Plant, res: Residuals) -> Judged:
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
        y_all = {s: res(apply_changes(res.sim, real_est, kept), s) for s in SEGMENTS}
        minus = {n: {s: res(apply_changes(res.sim, real_est,
                                          [r for r in kept if r.effect != n]), s)
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
    y0 = res.before["estimation"].y
    e0 = float(y0 @ y0)
    shares = {}
    for n, rs in by.items():
        y = res(apply_changes(res.sim, real_est, rs), "estimation")
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


Curve = tuple[FoundEffect, AxisModel]


def _unexplained(sim: PlantFitResult, real: PlantFitResult,
                 ) -> tuple[list[Curve], list[Curve], list[str]]:
    """Unexplained structure on an axis only one recording shows goes to that side."""
    def axes(f: PlantFitResult) -> dict[str, Curve]:
        return {str(e.params.get("axis")): (e, m) for e, m in f.curves}

    s_ax, r_ax = axes(sim), axes(real)
    notes = [f"both recordings show structure over {a} that no library effect explains; "
             "it is not compared" for a in r_ax if a in s_ax]
    return ([c for a, c in r_ax.items() if a not in s_ax],
            [c for a, c in s_ax.items() if a not in r_ax], notes)


def _best_curve(curves: list[Curve]) -> AxisModel | None:
    """The real-only curve that lowers the held-out error most (for the fit table)."""
    ok = [(e.held_out.reduction, m) for e, m in curves
          if e.held_out is not None and e.held_out.significant]
    return max(ok, key=lambda t: t[0])[1] if ok else None


def _rigid_cap(rows: list[Change], sim: PlantFitResult,
               real: PlantFitResult) -> list[Change]:
    """No 'high' mass or viscous change when a curve over thrust or speed explains one of
    the recordings better than (or beside) its rigid part."""
    if not (sim.rigid_capped or real.rigid_capped):
        return rows
    return [replace(r, confidence="moderate") if r.effect in RIGID_PARAMS
            and r.confidence == "high" else r for r in rows]


def _rigid_note(rows: list[Change], sim: PlantFitResult, real: PlantFitResult) -> list[str]:
    if not (sim.rigid_capped or real.rigid_capped) or not any(
            r.effect in RIGID_PARAMS and r.confidence == "high" for r in rows):
        return []
    side = "real" if real.rigid_capped else "simulated"
    return [f"mass and viscous changes are not 'high': a curve over thrust or speed explains "
            f"the {side} recording better than its rigid part alone"]


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


def _curves(before: dict[str, EquationData], after: dict[str, FloatArray],
            parts: dict[str, list[tuple[str, Any]]],
            replays: dict[str, dict[str, Any]]) -> Curves:
    c = Curves()
    for seg in SEGMENTS:
        d = before[seg]
        c.t[seg], c.x[seg], c.v[seg] = thinned_times(d), thinned(d, d.x), thinned(d, d.v)
        c.before[seg], c.after[seg] = d.y, after[seg]
        c.parts[seg] = parts[seg]
    c.replay.update(replays)
    return c


__all__ = ["diagnose_sim"]
