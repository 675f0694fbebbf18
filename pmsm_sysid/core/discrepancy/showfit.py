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

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..physics.plant import Plant
from ..validation.correlation import correlation_tests
from .estimate import Fit, contributions, design
from .kinematics import EquationData
from .locate import AxisFinding, scan_axes
from .nonparam import AxisModel, fit_axis
from .resim import Z_VERDICT, choose_horizon, compare
from .result import FoundEffect
from .select import Step
from .stats import HeldOutTest, ar_whitener, held_out_test, lstsq, nrmse, whiten

FloatArray = NDArray[np.float64]

MAX_LAG = 20


def where_table(data: EquationData, ranking: list[Step]) -> list[AxisFinding]:
    """Axis scan of the nominal residual, the position axis with its periodogram peak."""
    found = scan_axes(data, data.y, np.zeros((data.n, 0)))
    cog = next((s for s in ranking if s.effect.name == "cogging"), None)
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


def scan_unexplained(fit: Fit, data: EquationData, alpha: float, min_share: float,
                     est: tuple[Fit, EquationData], val: EquationData, thrust: bool,
                     ) -> list[tuple[FoundEffect, AxisModel]]:
    """Axes on which the final residual is still significantly structured, each with a
    curve fitted on the estimation data (:mod:`.nonparam`) and judged on held-out data."""
    X, fixed = design(fit.effects, data)
    found = scan_axes(data, data.y - fixed, X, total=float(data.y @ data.y),
                      null_whitening=True, thrust=thrust)
    out = []
    for f in found:
        if f.significance > -np.log10(alpha) and f.share >= min_share:
            model, held = _curve(f.axis, est, val)
            text = f"structure over {f.axis} that no library effect explains"
            conf = "moderate" if held.significant else "low"
            out.append((FoundEffect(
                "unexplained", {"axis": f.axis, **model.describe(), **f.details}, {},
                f.significance, f.share, held, conf, (text,)), model))
    return out


def _curve(axis: str, est: tuple[Fit, EquationData],
           val: EquationData) -> tuple[AxisModel, HeldOutTest]:
    """The best curve for ``axis`` on the estimation data, and its held-out test."""
    fit, d = est
    X, fixed = design(fit.effects, d)
    kinds = {"position": ("position", "position_friction"), "frequency": ("time",)}
    best: tuple[float, AxisModel] | None = None
    for kind in kinds.get(axis, (axis,)):
        m = fit_axis(d, d.y - fixed, X, kind)
        sse = float(np.sum((d.y - fixed - X @ lstsq(X, d.y - fixed - m.force(d))[0]
                            - m.force(d)) ** 2))
        if best is None or sse < best[0]:
            best = (sse, m)
    assert best is not None
    parts = contributions(fit, val)
    e0 = val.y - (np.sum(parts, axis=0) if parts else 0.0)
    return best[1], held_out_test(e0, e0 - best[1].force(val))


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
    horizon = choose_horizon((plant, corrected), segs.recs["estimation"]) if do_replay \
        else None
    for name, d in (("estimation", segs.est), ("validation", segs.val)):
        row = _segment_fit(fit, d, extra)
        if horizon is not None:
            rec = segs.recs[name]
            cmp = compare(plant, corrected, rec, horizon)
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
