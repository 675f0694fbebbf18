"""Figures of a fleet of axes: one axis's fitted plant parameters over time.

``axis_trends`` draws one panel per followed parameter of an axis: each recording's value
with its standard error, the baseline (median of the first recordings, dashed) and the band
around it (shaded), recordings out of band in red, and each alarm (the first recording of
an excursion) marked by a dotted red line at its time. ``data`` holds, per parameter, the
times (s since 1970, UTC), values, band edges, out-of-band flags and alarm times drawn.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from typing import Any

import numpy as np
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter

from ..core.fleet import AxisTrend, ParameterTrend
from .base import Plot, new_figure, styled

UNITS = (("_n_per_mps", "N·s/m"), ("_n_per_m", "N/m"), ("_mps", "m/s"), ("_kg", "kg"),
         ("_rad", "rad"), ("_n", "N"), ("_m", "m"), ("_s", "s"))
BASELINE_COLOUR = "0.35"
BAND_COLOUR = "tab:green"
OUT_COLOUR = "tab:red"
#: How a parameter's state reads in a panel's title.
STATE_WORDS = {"baseline": "baseline forming", "untracked": "not in most of the baseline: "
               "not compared", "ok": "ok", "alarm": "ALARM"}
#: Every figure of a fleet page is named ``trend_<axis>.png``.
FILE_PREFIX = "trend_"


class SteadyDateLocator(AutoDateLocator):
    """matplotlib's automatic date ticks, computed once per view interval.

    Laying out panels that share the time axis asks the (shared) locator for its ticks
    once per panel for each panel, in each pass: 290 times for the two figures of the
    bundled bags, a fifth of their drawing. The ticks depend on the view interval alone
    (and the time zone, fixed), so a repeated interval returns the ticks found for it.
    """

    def __init__(self) -> None:
        super().__init__()  # type: ignore[no-untyped-call]
        self._last: tuple[tuple[float, float], Any] | None = None

    def __call__(self) -> Any:
        axis: Any = self.axis
        lo, hi = (float(v) for v in axis.get_view_interval())
        if self._last is None or self._last[0] != (lo, hi):
            self._last = ((lo, hi), super().__call__())  # type: ignore[no-untyped-call]
        return np.array(self._last[1])


def label(parameter: str) -> str:
    """``coulomb_friction.amplitude_n (N)``: the parameter with its unit."""
    unit = next((u for suffix, u in UNITS if parameter.endswith(suffix)), "")
    return f"{parameter} ({unit})" if unit else parameter


def file_stem(axis: str) -> str:
    """A file name for an axis's figure (``trend_axis1``; other characters become ``_``)."""
    slug = re.sub(r"[^A-Za-z0-9]+", "_", axis).strip("_") or "root"
    return FILE_PREFIX + slug


def _dates(seconds: Any) -> list[datetime]:
    return [datetime.fromtimestamp(float(s), UTC) for s in seconds]


def _panel(ax: Any, p: ParameterTrend) -> dict[str, Any]:
    t = np.asarray([q.start_time for q in p.points])
    v = np.asarray([q.value for q in p.points])
    err = np.asarray([q.std if q.std is not None else 0.0 for q in p.points])
    out = np.asarray([q.out for q in p.points], dtype=bool)
    banded = [q for q in p.points if q.lo is not None and q.hi is not None]
    lo = np.asarray([q.lo for q in banded], dtype=np.float64)
    hi = np.asarray([q.hi for q in banded], dtype=np.float64)
    tb = np.asarray([q.start_time for q in banded])
    if len(banded):
        ax.fill_between(_dates(tb), lo, hi, color=BAND_COLOUR, alpha=0.18, step="mid",
                        label="band", linewidth=0)
    if p.baseline is not None:
        ax.axhline(p.baseline, color=BASELINE_COLOUR, linestyle="--", linewidth=0.8,
                   label="baseline")
    base = np.asarray([q.baseline for q in p.points], dtype=bool)
    for mask, style in ((base, {"mfc": "white", "label": "baseline recordings"}),
                        (~base & ~out, {"label": "in band"}),
                        (out, {"color": OUT_COLOUR, "label": "out of band"})):
        if mask.any():
            ax.errorbar(_dates(t[mask]), v[mask], yerr=err[mask], fmt="o", markersize=3.5,
                        capsize=2, linewidth=0.8, **({"color": "tab:blue"} | style))
    ta = np.asarray([a.start_time for a in p.alarms])
    for i, when in enumerate(_dates(ta)):
        ax.axvline(when, color=OUT_COLOUR, linestyle=":", linewidth=1.2,
                   label="alarm" if i == 0 else None)
    ax.set_ylabel(label(p.parameter), fontsize=7)
    ax.set_title(f"{p.parameter}: {STATE_WORDS.get(p.state, p.state)}", fontsize=8,
                 loc="left")
    return {"t": t, "value": v, "std": err, "band_t": tb, "lo": lo, "hi": hi, "out": out,
            "alarms": ta, "baseline": p.baseline}


@styled
def axis_trends(trend: AxisTrend) -> Plot:
    """One panel per followed parameter of ``trend``'s axis, over the recordings' times."""
    params = [p for p in trend.parameters if p.points]
    fig = new_figure(8.0, 0.6 + 1.7 * max(1, len(params)))
    axes = np.atleast_1d(fig.subplots(max(1, len(params)), 1, sharex=True, squeeze=False)[:, 0])
    data: dict[str, Any] = {}
    for ax, p in zip(axes, params, strict=False):
        data[p.parameter] = _panel(ax, p)
    locator = SteadyDateLocator()
    axes[-1].xaxis.set_major_locator(locator)
    axes[-1].xaxis.set_major_formatter(
        ConciseDateFormatter(locator))  # type: ignore[no-untyped-call]
    axes[-1].set_xlabel("start of the recording (UTC)")
    if params:
        axes[0].legend(loc="best", fontsize=6, ncols=3)
    n_alarms = sum(len(p.alarms) for p in params)
    return Plot(fig, file_stem(trend.axis),
                f"Axis {trend.axis}: each followed parameter of its fitted plant over time, "
                f"with its standard error; dashed: the baseline (median of the first "
                f"recordings, open circles); shaded: the band; red: out of band; dotted red "
                f"lines: the {n_alarms} alarm(s), each at the first recording out of band.",
                data)
