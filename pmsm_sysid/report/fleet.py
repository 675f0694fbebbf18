"""The page of a fleet of axes: ``DIR/index.html`` beside ``results.parquet``.

One self-contained page (figures embedded; the PNGs are also kept beside it): a table of the
axes with their latest values and state, the alarms, then per axis its parameters over time
(:func:`pmsm_sysid.plots.fleet.axis_trends`) and its failed recordings.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..core.fleet import MAGNITUDE, AxisTrend, TrendOptions, spread_factor
from ..plots import save
from ..plots.fleet import FILE_PREFIX, axis_trends
from .html import Block, Note, Section, Table, image, render_page


def _when(seconds: Any) -> str:
    if seconds is None:
        return "n/a"
    return datetime.fromtimestamp(float(seconds), UTC).strftime("%Y-%m-%d %H:%M:%S")


def _v(x: Any) -> str:
    return "" if x is None else f"{x:.5g}" if isinstance(x, float) else str(x)


def _latest_ok(rows: Sequence[Mapping[str, Any]], axis: str) -> Mapping[str, Any]:
    mine = [r for r in rows if r.get("axis") == axis and r.get("status") == "ok"]
    return max(mine, key=lambda r: r.get("start_time") or 0.0, default={})


def _value_columns(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """mass, viscous, and the size of every effect found on some axis."""
    found = [f"{e}.{p}" for e, p in MAGNITUDE.items()
             if any(r.get(f"{e}.{p}") is not None for r in rows)]
    return ["mass_kg", "viscous_n_per_mps", *found]


def _state(t: AxisTrend, options: TrendOptions) -> str:
    if t.state == "baseline":
        return f"baseline forming ({t.recordings} of {options.baseline} recordings)"
    if t.state == "alarm":
        return "ALARM: " + ", ".join(
            p.parameter + (f" since {_when(p.alarms[-1].start_time)}" if p.alarms else "")
            for p in t.in_alarm)
    return "ok"


def axes_table(trends: Sequence[AxisTrend], rows: Sequence[Mapping[str, Any]],
               options: TrendOptions) -> Table:
    """Per axis: recordings, failed ones, the latest, the state, the latest values."""
    cols = _value_columns(rows)
    out = []
    for t in trends:
        mine = [r for r in rows if r.get("axis") == t.axis]
        latest = _latest_ok(rows, t.axis)
        failed = sum(1 for r in mine if r.get("status") != "ok")
        out.append((t.axis, str(len(mine)), str(failed), _when(latest.get("start_time")),
                    _state(t, options), *(_v(latest.get(c)) for c in cols)))
    named = {str(r["axis"]) for r in rows if r.get("axis") is not None}
    for axis in sorted(named - {t.axis for t in trends}):
        n = sum(1 for r in rows if r.get("axis") == axis)
        out.append((axis, str(n), str(n), "n/a", "no recording analysed", *([""] * len(cols))))
    return Table("Axes: the latest recording analysed and its fitted plant (state: ALARM "
                 "while a parameter's latest value is out of its band)",
                 ("axis", "recordings", "failed", "latest (UTC)", "state", *cols), tuple(out))


def alarms_table(trends: Sequence[AxisTrend]) -> Table:
    alarms = sorted((a for t in trends for a in t.alarms), key=lambda a: a.start_time)
    return Table("Alarms: each at the first recording of an excursion out of the band",
                 ("axis", "parameter", "recording", "start (UTC)", "value", "baseline",
                  "band"),
                 tuple((a.axis, a.parameter, a.recording, _when(a.start_time), _v(a.value),
                        _v(a.baseline), f"{a.band[0]:.5g} .. {a.band[1]:.5g}")
                       for a in alarms))


def _failed(rows: Sequence[Mapping[str, Any]], axis: str | None) -> Table | None:
    bad = [r for r in rows if r.get("axis") == axis and r.get("status") != "ok"]
    if not bad:
        return None
    return Table("Recordings that could not be analysed", ("recording", "start (UTC)", "reason"),
                 tuple((str(r.get("recording")), _when(r.get("start_time")),
                        str(r.get("error"))) for r in bad))


def _method(options: TrendOptions) -> Note:
    factor = spread_factor(options.baseline, options.z)
    return Note(
        f"Baseline: the median of each parameter over an axis's first {options.baseline} "
        "recordings; its spread σ is their standard deviation with an odd one left out. "
        f"Band: the baseline ± √((t σ)² (1 + π/(2n)) + ({options.z:g} s)²), s the "
        f"recording's own standard error, t Student's quantile for the n baseline values at "
        f"the level of {options.z:g} standard deviations (t √(1 + π/(2n)) = {factor:.3g} for "
        f"{options.baseline}), never narrower than ± {options.min_change:.0%} of the "
        "baseline. An effect not found counts as size zero, so an effect that appears (or "
        "vanishes) leaves the band. Phases are not followed.")


def write_fleet_report(out: str | Path, trends: Sequence[AxisTrend],
                       rows: Sequence[Mapping[str, Any]], *, title: str,
                       options: TrendOptions | None = None) -> Path:
    """Write the figures and ``out/index.html`` (atomically); return the page's path."""
    from ..validate import atomic_write_text

    opts = TrendOptions() if options is None else options
    out = Path(out)
    keep: set[str] = set()
    sections = [Section("Axes", (axes_table(trends, rows, opts), alarms_table(trends),
                                 _method(opts)))]
    for t in trends:
        plot = axis_trends(t)
        path = save(plot, out)
        keep.add(path.name)
        blocks: list[Block] = [image(path, plot.caption)]
        failed = _failed(rows, t.axis)
        if failed is not None:
            blocks.append(failed)
        sections.append(Section(f"Axis {t.axis}: {_state(t, opts)}", tuple(blocks)))
    unanalysed = _failed(rows, None)
    if unanalysed is not None:
        sections.append(Section("Recordings whose axis could not be read", (unanalysed,)))
    for stale in out.glob(FILE_PREFIX + "*.png"):
        if stale.name not in keep:
            stale.unlink()
    page = out / "index.html"
    n = len({r.get("recording") for r in rows})
    atomic_write_text(page, render_page(title, sections, subtitle=(
        f"{len(trends)} axes, {n} recordings, {len(rows)} rows")), "--out")
    return page
