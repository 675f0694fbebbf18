"""Before/after evidence: where the mismatch lives, what is left, and the fit table.

* ``where_table``: the axis scan of the nominal residual (:mod:`.locate`), with the position
  periodogram's peak (the best cogging pitch of the ERR ranking) added to the position axis
  (its share and significance are the larger of the bins' and the period's).
* ``scan_unexplained``: the same scan on the final model's residual; an axis that still
  explains a significant share becomes an ``unexplained`` entry saying where it lives.
* ``fit_table``: force (equation-error) NRMSE before/after, the Billings-Voon tests (Eq.
  13 of Liu et al. 2005) on the residual prewhitened by the final model's AR filter (the same
  filter before and after, so only the model changes), and the short-horizon speed replay (output
  error,
  :mod:`.resim`: horizon chosen so that position-periodic forces are evaluated where they
  act, and a verdict -- ``replay_notes`` says so where the replay cannot see the
  correction).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..physics.plant import Plant
from ..plantfit.estimate import Fit, contributions, design, remainder_of
from ..plantfit.found import FoundEffect
from ..plantfit.kinematics import EquationData, thinned_sizes
from ..plantfit.library import columns
from ..plantfit.select import Step
from ..plantfit.stats import (
    HeldOutTest,
    ar_whitener,
    held_out_test,
    lstsq,
    nested_f_test,
    nrmse,
    whiten,
)
from ..validation.correlation import correlation_tests
from .local import local_grid, local_share
from .locate import AxisFinding, scan_axes
from .nonparam import AxisModel, beside_thrust, fit_axis, fit_axis_with
from .resim import Z_VERDICT, Replays, choose_horizon, compare

FloatArray = NDArray[np.float64]

MAX_LAG = 20


def where_table(data: EquationData, ranking: list[Step]) -> list[AxisFinding]:
    """Axis scan of the nominal residual, the position axis with its periodogram peak."""
    cog = next((s for s in ranking if s.effect.name == "cogging"), None)
    period = None if cog is None else {"position": (columns(cog.effect, data), cog.share)}
    found = scan_axes(data, data.y, np.zeros((data.n, 0)), extra=period)
    out = []
    for f in found:
        if f.axis == "position" and cog is not None:
            sig = cog.significance
            extra = {"period_m": cog.effect.pitch_m, "period_share": cog.share,
                     "period_significance": sig, "bins_share": f.share,
                     "bins_significance": f.significance}
            # 16 bins cannot draw a period shorter than a few bin widths: the axis is
            # described by whichever of the two bases (bins, best period) sees more
            f = AxisFinding(f.axis, max(f.share, cog.share), max(f.significance, sig),
                            {**extra, **f.details})
        out.append(f)
    return out


CURVE_KINDS = {"position": ("position", "position_friction", "position_local"),
               "velocity": ("velocity",), "thrust": ("thrust",), "frequency": ("time",),
               "time": ("time",)}


def scan_unexplained(fit: Fit, data: EquationData, alpha: float, min_share: float,
                     est: tuple[Fit, EquationData], val: EquationData, closed: bool,
                     lean: bool = False) -> list[tuple[FoundEffect, AxisModel]]:
    """Axes on which the final residual is still significantly structured, each with a
    curve fitted on the estimation data (:mod:`.nonparam`) and judged on held-out data.

    Over position and velocity (and over thrust under feedback, against a straight line
    over thrust) the axis is tested with its generic bins and with each curve's own
    filtered columns (a local bump: Bonferroni over the members scanned too), Bonferroni
    over all; the curves are smooth and pass through the parallel filter like every
    regressor, so they see what 16 bins blur. The most significant curve models the axis.
    Over thrust open loop only the rivals judge (:mod:`.rival`): a thrust sensor's noise
    is in both the residual and the recorded thrust, and its bend needs no loop -- unless
    ``lean`` (with ``closed``): the thrust is then scanned open loop against the line and
    the reading noise's own bend beside it (:mod:`.nonparam`).
    """
    X, fixed = design(fit.effects, data)
    y = data.y - fixed - remainder_of(fit, data)
    found = scan_axes(data, y, X, total=float(data.y @ data.y), null_whitening=True)
    axes = ["position", "velocity"] + (["thrust"] if closed else [])
    n_tests = len(found) + sum(len(CURVE_KINDS[a]) for a in axes)
    tested = {f.axis: f for f in found}
    if closed:
        tested["thrust"] = AxisFinding("thrust", 0.0, 0.0, {})
    out = []
    for axis, f in tested.items():
        sig, share = f.significance - np.log10(n_tests / (len(found) + 1)), f.share
        relevant = share
        if axis == "frequency":  # a line's relevance is judged where it lives: among its
            relevant = max(share, float(f.details.get("line_local_share", 0.0)))  # neighbours
        kinds = CURVE_KINDS[axis]
        if axis in axes:
            sig_c, share_c, kind = _curve_evidence(axis, data, y, X, n_tests, closed, lean)
            sig, share, kinds = max(sig, sig_c), max(share, share_c), (kind,)
            relevant = share
        if sig > -np.log10(alpha) and relevant >= min_share:
            model, held = _curve(kinds, est, val, closed,
                                 float(f.details.get("line_hz", 0.0)) if axis == "frequency"
                                 else 0.0, lean)
            text = f"structure over {axis} that no library effect explains"
            conf = "moderate" if held.significant else "low"
            out.append((FoundEffect(
                "unexplained", {"axis": axis, **model.describe(), **f.details}, {},
                sig, share, held, conf, (text,)), model))
    part = min(thinned_sizes(data) or (data.n,))  # a line's bin is a part's (spans)
    return _one_sinusoid(out, part / data.sample_rate_hz)


def beside_curves(out: list[tuple[FoundEffect, AxisModel]], more: list[AxisModel],
                  est: tuple[Fit, EquationData], val: EquationData,
                  ) -> list[tuple[FoundEffect, AxisModel]]:
    """A sinusoid over time judged beside the confirmed curves over the other axes (those
    of ``out`` and ``more``, the curves that beat a library group).

    A force over position met on a repeated move comes back with the move's period, so
    its line shows over time too (on the EMPS rig: the end-of-stroke force as a 0.32 Hz
    "disturbance"). The sinusoid keeps its place only if, fitted with those curves, it
    still lowers the held-out error; its held-out test becomes that conditional one.
    """
    others = [m for e, m in out if m.axis != "time" and e.held_out is not None
              and e.held_out.significant] + more
    if not others or all(m.axis != "time" for _, m in out):
        return out
    fit, d = est
    X, fixed = design(fit.effects, d)
    y = d.y - fixed - remainder_of(fit, d)
    base = np.hstack([X, *(m.projected(d) for m in others)])
    parts = contributions(fit, val)
    e_lib = val.y - (np.sum(parts, axis=0) if parts else 0.0)
    result = []
    for e, m in out:
        if m.axis == "time":
            sine, beta, _ = fit_axis_with(d, y, base, "time", freq_hz=m.freq_hz)
            curves = np.hstack([c.projected(val) for c in others])
            e0 = e_lib - curves @ beta[X.shape[1]:]
            held = held_out_test(e0, e0 - sine.force(val))
            e = replace(e, held_out=held, confidence="moderate" if held.significant
                        else "low")
        result.append((e, m))
    return result


def _one_sinusoid(out: list[tuple[FoundEffect, AxisModel]], span: float,
                  ) -> list[tuple[FoundEffect, AxisModel]]:
    """The time and the frequency axis modelled by the same sinusoid (within one
    frequency bin) are one finding: the better on held-out data is kept."""
    sines = [item for item in out if item[1].axis == "time"]
    if len(sines) < 2 or abs(sines[0][1].freq_hz - sines[1][1].freq_hz) > 1.0 / span:
        return out

    def score(item: tuple[FoundEffect, AxisModel]) -> float:
        h = item[0].held_out
        return -np.inf if h is None else h.reduction

    drop = min(sines, key=score)
    return [item for item in out if item is not drop]


def _curve_evidence(axis: str, data: EquationData, y: FloatArray, X: FloatArray,
                    n_tests: float, line: bool, lean: bool = False,
                    ) -> tuple[float, float, str]:
    """Significance (-log10 corrected p, null whitening), share and kind of the most
    significant curve on ``axis`` (over thrust: beyond the line and, with ``lean``, the
    reading noise's bend)."""
    best = (0.0, 0.0, CURVE_KINDS[axis][0])
    base = np.hstack([X, beside_thrust(data, lean)]) if axis == "thrust" and line else X
    total = float(data.y @ data.y)
    for kind in CURVE_KINDS[axis]:
        m = fit_axis(data, y, X, kind, line, lean)
        cols = m.projected(data)
        searched = local_grid(data)[1] if kind == "position_local" else 1.0
        test = nested_f_test(y, base, cols, null_whitening=True)
        sig = -test.corrected_log10_p(n_tests * searched)
        r0 = lstsq(base, y)[1]
        r1 = lstsq(np.hstack([base, cols]), y)[1]
        share = float(r0 @ r0 - r1 @ r1) / total
        if kind == "position_local":  # a local force: relevant where it acts
            share = max(share, local_share(data, *m.bump, r0, r1))
        best = max(best, (sig, share, kind))
    return best


def _curve(kinds: tuple[str, ...], est: tuple[Fit, EquationData], val: EquationData,
           line: bool = False, freq_hz: float = 0.0,
           lean: bool = False) -> tuple[AxisModel, HeldOutTest]:
    """The best curve of ``kinds`` on the estimation data (least residual energy), and its
    held-out test (against the line over thrust alone, when there is one). Over frequency
    the curve is the sinusoid at the line found (``freq_hz``)."""
    fit, d = est
    X, fixed = design(fit.effects, d)
    best: tuple[float, AxisModel] | None = None
    for kind in kinds:
        m, _, sse = fit_axis_with(d, d.y - fixed - remainder_of(fit, d), X, kind, line,
                                  freq_hz, lean)
        if best is None or sse < best[0]:
            best = (sse, m)
    assert best is not None
    parts = contributions(fit, val)
    e0 = val.y - (np.sum(parts, axis=0) if parts else 0.0)
    model = best[1]
    return model, held_out_test(e0 - model.baseline(val), e0 - model.force(val))


def _segment_fit(fit: Fit, d: EquationData, extra: AxisModel | None) -> dict[str, Any]:
    parts = contributions(fit, d)
    after = d.y - (np.sum(parts, axis=0) if parts else 0.0)
    if extra is not None:
        after = after - extra.force(d)
    target = d.project(d.force)
    poly = ar_whitener(after)
    u = d.project(d.force)[len(poly) - 1:]
    tests = {}
    for name, e in (("before", d.y), ("after", after)):
        ew = whiten(poly, e)
        tests[name] = correlation_tests(ew, u, max_lag=min(MAX_LAG, len(ew) // 4)).to_dict()
    return {"nrmse_before": nrmse(target, d.y), "nrmse_after": nrmse(target, after),
            "correlation_tests": tests, "samples": d.n}


def fit_table(plant: Plant, corrected: Plant, fit: Fit, segs: Any, do_replay: bool,
              extra: AxisModel | None = None,
              ) -> tuple[dict[str, Any], dict[str, dict[str, FloatArray]]]:
    """The diagnose JSON's ``fit`` block (plus tests and output error) and replay series.

    The replay horizon is chosen once, on the estimation recording (:func:`.resim.
    choose_horizon`), and kept for the held-out data so both rows measure the same thing.
    """
    table: dict[str, Any] = {}
    replays: dict[str, dict[str, FloatArray]] = {}
    def sizes(name: str) -> tuple[int, ...]:
        pieces = segs.pieces(name)
        return tuple(len(p) for p in pieces) if len(pieces) > 1 else ()

    kept: Replays = {}  # the estimation recording's replays, drift and comparison alike
    horizon = choose_horizon((plant, corrected), segs.recs["estimation"],
                             parts=sizes("estimation"), kept=kept) if do_replay else None
    for name, d in (("estimation", segs.est), ("validation", segs.val)):
        row = _segment_fit(fit, d, extra)
        if horizon is not None:
            rec = segs.recs[name]
            cmp = compare(plant, corrected, rec, horizon, sizes(name),
                          kept if name == "estimation" else None)
            row["output_error"] = cmp.to_dict()
            replays[name] = {"t": rec.t, "measured": rec.speed, "before": cmp.before.speed,
                             "after": cmp.after.speed}
        table[name] = row
    return table, replays


def replay_notes(table: dict[str, Any], named: list[str]) -> list[str]:
    """Say so where the speed replay does not show the correction (instead of printing a
    worse or unchanged number without comment)."""
    out = []
    what = ", ".join(named) or "the correction"
    for seg in ("estimation", "validation"):
        oe = (table.get(seg) or {}).get("output_error")
        if not oe or oe["verdict"] in ("better", "same"):
            continue
        hz = oe["horizon"]
        z = "n/a" if oe["z"] is None else f"{oe['z']:.1f}"
        head = (f"speed replay on {seg} data ({oe['horizon_s']:.3g} s horizons; "
                f"{hz['reason']}): ")
        if oe["verdict"] == "worse":
            out.append(head + f"the corrected plant replays worse (z = {z}); the replay does "
                       f"not support {what} here -- the force fit and the held-out test are "
                       "the evidence")
        else:
            out.append(head + f"the change is within the replay's noise (|z| = {z} < "
                       f"{Z_VERDICT}): the replay cannot see {what} at this noise level")
    return out
