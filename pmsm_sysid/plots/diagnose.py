"""Figures of a sim-to-real diagnosis (``pmsm-sysid diagnose --report DIR``).

=======================  ====================================================================
function                 shows
=======================  ====================================================================
``residual_time``        force residual of the nominal and of the corrected plant over time
``residual_vs_axis``     partial residual over position or velocity, each named effect's
                         fitted curve drawn over it
``speed_replay``         measured speed and the short-horizon replays before/after
``fit_bars``             NRMSE before/after, estimation and held-out, force and speed
``effect_before_after``  one named effect: the residual without it and with it, side by
                         side over the effect's own axis, its fitted curve over the first
``unexplained_curve``    an ``unexplained`` force: the curve the diagnose JSON keeps of it
                         over its axis (positions in mm), its region shaded
=======================  ====================================================================

Each returns a :class:`~.base.Plot` whose ``data`` holds what was drawn, read back from the
artists. :func:`pmsm_sysid.report.diagnose.write_report` saves them with the report tables.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..core.discrepancy.result import DiagnoseResult
from .base import Plot, new_figure, styled

FloatArray = NDArray[np.float64]

POSITION_EFFECTS = ("cogging", "thrust_ripple", "spring")
VELOCITY_EFFECTS = ("coulomb_friction", "stribeck_friction", "viscous_error", "force_offset")


def _gapped(t: FloatArray, *ys: FloatArray) -> tuple[FloatArray, ...]:
    """The series with a NaN at every gap between the spans of a long recording (a jump in
    time of more than five steps), so that no line is drawn across it."""
    t = np.asarray(t, dtype=np.float64)
    if len(t) < 3:
        return (t, *ys)
    dt = np.diff(t)
    at = np.flatnonzero(dt > 5.0 * float(np.median(dt))) + 1
    if not len(at):
        return (t, *ys)
    return tuple(np.insert(np.asarray(s, dtype=np.float64), at, np.nan) for s in (t, *ys))


@styled
def residual_time(result: DiagnoseResult) -> Plot:
    """Residual before (grey) and after (black) over time; one panel per data segment."""
    c = result.curves
    segs = [s for s in ("estimation", "validation") if s in c.t]
    fig = new_figure(8.0, 2.4 * max(1, len(segs)))
    axes = np.atleast_1d(fig.subplots(len(segs), 1, squeeze=False)[:, 0])
    data: dict[str, Any] = {}
    for ax, seg in zip(axes, segs, strict=True):
        t, before, after = _gapped(c.t[seg], c.before[seg], c.after[seg])
        (b,) = ax.plot(t, before, color="0.6", label="nominal plant")
        (a,) = ax.plot(t, after, color="k", label="corrected")
        ax.set_ylabel("force residual (N)")
        ax.set_title(f"{seg} data")
        ax.legend(loc="upper right")
        data[seg] = {"t": np.asarray(b.get_xdata()), "before": np.asarray(b.get_ydata()),
                     "after": np.asarray(a.get_ydata())}
    axes[-1].set_xlabel("time (s)")
    return Plot(fig, "diagnose_residual_time",
                "Equation-error force residual (parallel-filtered) of the nominal plant and "
                "of the corrected plant.", data)


@styled
def residual_vs_axis(result: DiagnoseResult, axis: str, segment: str = "estimation") -> Plot:
    """Partial residual over ``position`` or ``velocity`` with the named effects' curves.

    The partial residual is what is left after the model plus the effects of this axis: the
    points scatter around the drawn curve when the named effect has the right shape.
    """
    c = result.curves
    names = POSITION_EFFECTS if axis == "position" else VELOCITY_EFFECTS
    arg = c.x[segment] if axis == "position" else c.v[segment]
    parts = [(n, p) for n, p in c.parts.get(segment, []) if n in names]
    effect = np.sum([p for _, p in parts], axis=0) if parts else np.zeros_like(arg)
    partial = c.after[segment] + effect
    order = np.argsort(arg)
    fig = new_figure(8.0, 3.2)
    ax = fig.subplots()
    (pts,) = ax.plot(arg * (1e3 if axis == "position" else 1.0), partial, ".", color="0.5",
                     markersize=2, label="residual + these effects")
    data: dict[str, Any] = {"arg": np.asarray(pts.get_xdata()),
                            "partial": np.asarray(pts.get_ydata()), "curves": {}}
    if parts:
        label = " + ".join(n for n, _ in parts)
        (line,) = ax.plot(arg[order] * (1e3 if axis == "position" else 1.0), effect[order],
                          color="tab:red", label=f"fitted: {label}")
        data["curves"][label] = np.asarray(line.get_ydata())
    ax.set_xlabel("position (mm)" if axis == "position" else "speed (m/s)")
    ax.set_ylabel("force (N)")
    ax.set_title(f"residual over {axis} ({segment} data)")
    ax.legend(loc="upper right")
    return Plot(fig, f"diagnose_residual_vs_{axis}",
                f"Residual over {axis} after every other effect, with the fitted curve of "
                f"the named {axis} effects ({', '.join(n for n, _ in parts) or 'none'}).",
                data)


@styled
def speed_replay(result: DiagnoseResult, segment: str = "validation",
                 seconds: float = 1.0) -> Plot:
    """Measured speed and the replays of the nominal and corrected plants (first seconds)."""
    r = result.curves.replay.get(segment)
    fig = new_figure(8.0, 3.0)
    ax = fig.subplots()
    data: dict[str, Any] = {}
    if r is not None:
        t = r["t"] - r["t"][0]
        keep = t <= seconds
        for key, style in (("measured", "0.6"), ("before", "tab:blue"), ("after", "k")):
            (line,) = ax.plot(t[keep], r[key][keep], color=style, label=key)
            data[key] = np.asarray(line.get_ydata())
    ax.set_xlabel("time (s)")
    ax.set_ylabel("speed (m/s)")
    oe = (result.fit.get(segment) or {}).get("output_error") or {}
    every = f" every {oe['horizon_s']:.3g} s" if "horizon_s" in oe else ""
    ax.set_title(f"speed replay from the measured state{every} ({segment} data)")
    ax.legend(loc="upper right")
    return Plot(fig, "diagnose_speed_replay",
                "Recorded thrust replayed through the nominal (before) and corrected (after) "
                "plants, restarted from the measured state every horizon (short enough "
                "that position-periodic forces are evaluated where they act).", data)


@styled
def fit_bars(result: DiagnoseResult) -> Plot:
    """NRMSE before/after for force and speed, estimation and held-out data."""
    labels, before, after = [], [], []
    for seg in ("estimation", "validation"):
        f = result.fit.get(seg) or {}
        rows = [("force", f)]
        if f.get("output_error"):
            rows.append(("speed", f["output_error"]))
        for kind, row in rows:
            labels.append(f"{kind}\n{seg}")
            before.append(float(row["nrmse_before"]))
            after.append(float(row["nrmse_after"]))
    fig = new_figure(6.0, 3.0)
    ax = fig.subplots()
    x = np.arange(len(labels))
    b = ax.bar(x - 0.2, before, 0.4, color="0.6", label="nominal plant")
    a = ax.bar(x + 0.2, after, 0.4, color="k", label="corrected")
    ax.set_xticks(x, labels)
    ax.set_ylabel("NRMSE")
    ax.legend()
    return Plot(fig, "diagnose_fit", "NRMSE before and after the named effects.",
                {"labels": labels, "before": [float(r.get_height()) for r in b],
                 "after": [float(r.get_height()) for r in a]})


def _effect_axis(name: str) -> tuple[str, str, float]:
    """(curves attribute, axis label, scale) of the axis an effect depends on."""
    if name in POSITION_EFFECTS:
        return "x", "position (mm)", 1e3
    if name in VELOCITY_EFFECTS:
        return "v", "speed (m/s)", 1.0
    return "t", "time (s)", 1.0


@styled
def effect_before_after(result: DiagnoseResult, name: str,
                        segment: str = "estimation") -> Plot:
    """The force residual without the effect ``name`` modelled (left, with its fitted curve)
    and with it (right), over the quantity the effect depends on. DataError when the
    diagnosis has no fitted curve of that effect."""
    from ..core.errors import DataError

    c = result.curves
    part = dict(c.parts.get(segment, [])).get(name)
    if part is None:
        raise DataError(f"{name}: the diagnosis holds no fitted curve of it")
    attr, label, scale = _effect_axis(name)
    arg = np.asarray(getattr(c, attr)[segment]) * scale
    after = c.after[segment]
    before = after + part
    fig = new_figure(8.0, 3.0)
    left, right = fig.subplots(1, 2, sharey=True)
    (pb,) = left.plot(arg, before, ".", color="0.5", markersize=2, label="residual")
    order = np.argsort(arg)
    (curve,) = left.plot(arg[order], part[order], color="tab:red", label=f"fitted {name}")
    (pa,) = right.plot(arg, after, ".", color="k", markersize=2, label="residual")
    left.set_title(f"before: {name} not modelled")
    right.set_title(f"after: {name} modelled")
    left.set_ylabel("force residual (N)")
    for ax in (left, right):
        ax.set_xlabel(label)
        ax.legend(loc="upper right")
    return Plot(fig, f"effect_{name}",
                f"{name}: force residual of the {segment} data over {label.split(' (')[0]} "
                "before (left, the fitted curve in red) and after (right) it is modelled.",
                {"arg": np.asarray(pb.get_xdata()), "before": np.asarray(pb.get_ydata()),
                 "after": np.asarray(pa.get_ydata()), "curve": np.asarray(curve.get_ydata())})


AXIS_LABELS = {"m": ("position (mm)", 1e3), "m/s": ("speed (m/s)", 1.0),
               "N": ("thrust (N)", 1.0), "s": ("time (s)", 1.0)}


@styled
def unexplained_curve(params: dict[str, Any]) -> Plot:
    """The curve an ``unexplained`` entry keeps (``curve``: ``at``, ``force_n``) over its
    axis, with its region shaded. DataError when the entry holds no curve."""
    from ..core.errors import DataError

    curve = params.get("curve") or {}
    at, force = curve.get("at") or [], curve.get("force_n") or []
    if len(at) < 2 or len(at) != len(force):
        raise DataError("unexplained: the diagnosis keeps no curve of it")
    label, scale = AXIS_LABELS.get(str(params.get("unit", "")), (str(params.get("axis")), 1.0))
    fig = new_figure(6.0, 3.0)
    ax = fig.subplots()
    x = np.asarray(at, dtype=np.float64) * scale
    (line,) = ax.plot(x, force, color="tab:red", marker=".", label="unexplained force")
    region = params.get("region")
    if region:
        ax.axvspan(float(region[0]) * scale, float(region[1]) * scale, color="0.85",
                   label="where it stands out")
    ax.set_xlabel(label)
    ax.set_ylabel("force (N)")
    ax.legend(loc="best")
    what = label.split(" (")[0]
    return Plot(fig, "effect_unexplained",
                f"unexplained: the force left after the named effects, over {what}, as a "
                "smooth curve (shaded: where it stands out from the rest).",
                {"x": np.asarray(line.get_xdata()), "force": np.asarray(line.get_ydata())})


def figures(result: DiagnoseResult) -> list[Plot]:
    """Every figure of the diagnosis, in page order."""
    out = [fit_bars(result), residual_time(result),
           residual_vs_axis(result, "position"), residual_vs_axis(result, "velocity")]
    if result.curves.replay:
        out.append(speed_replay(result))
    return out

