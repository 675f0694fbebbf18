"""Before/after evidence: where the mismatch lives, what is left, and the fit table.

* ``where_table``: the axis scan of the nominal residual (:mod:`.locate`), with the position
  periodogram's peak (the best cogging pitch of the ERR ranking) added to the position axis
  (its share and significance are the larger of the bins' and the period's).
* ``scan_unexplained``: the same scan on the final model's residual; an axis that still
  explains a significant share becomes an ``unexplained`` entry saying where it lives.
* ``fit_table``: force (equation-error) NRMSE before/after, the Billings-Voon tests (seed
  Eq. 13) on the residual prewhitened by the final model's AR filter (the same filter before
  and after, so only the model changes), and the short-horizon speed replay (output error).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..plant import Plant
from ..validation import correlation_tests
from .estimate import Fit, contributions, design
from .kinematics import EquationData
from .locate import AxisFinding, scan_axes
from .resim import replay
from .result import FoundEffect
from .select import Step
from .stats import ar_whitener, nrmse, whiten

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


def scan_unexplained(fit: Fit, data: EquationData, alpha: float,
                     min_share: float) -> list[FoundEffect]:
    """Axes on which the final residual is still significantly structured."""
    X, fixed = design(fit.effects, data)
    found = scan_axes(data, data.y - fixed, X, total=float(data.y @ data.y),
                      null_whitening=True)
    out = []
    for f in found:
        if f.significance > -np.log10(alpha) and f.share >= min_share:
            out.append(FoundEffect(
                "unexplained", {"axis": f.axis, **f.details}, {}, f.significance, f.share,
                None, "moderate",
                (f"structure over {f.axis} that no library effect explains",)))
    return out


def _segment_fit(fit: Fit, d: EquationData) -> dict[str, Any]:
    parts = contributions(fit, d)
    after = d.y - (np.sum(parts, axis=0) if parts else 0.0)
    target = d.project(d.force)
    poly = ar_whitener(after)
    u = d.project(d.force)[len(poly) - 1:]
    tests = {}
    for name, e in (("before", d.y), ("after", after)):
        ew = whiten(poly, e)
        tests[name] = correlation_tests(ew, u, max_lag=min(MAX_LAG, len(ew) // 4)).to_dict()
    return {"nrmse_before": nrmse(target, d.y), "nrmse_after": nrmse(target, after),
            "correlation_tests": tests, "samples": d.n}


def fit_table(plant: Plant, corrected: Plant, fit: Fit, segs: Any,
              do_replay: bool) -> tuple[dict[str, Any], dict[str, dict[str, FloatArray]]]:
    """The contract's ``fit`` block (plus tests and output error) and replay series."""
    table: dict[str, Any] = {}
    replays: dict[str, dict[str, FloatArray]] = {}
    for name, d in (("estimation", segs.est), ("validation", segs.val)):
        row = _segment_fit(fit, d)
        if do_replay:
            rec = segs.recs[name]
            before, after = replay(plant, rec), replay(corrected, rec)
            row["output_error"] = {"signal": "speed", "horizon_s": before.horizon_s,
                                   "nrmse_before": before.nrmse, "nrmse_after": after.nrmse}
            replays[name] = {"t": rec.t, "measured": rec.speed, "before": before.speed,
                             "after": after.speed}
        table[name] = row
    return table, replays
