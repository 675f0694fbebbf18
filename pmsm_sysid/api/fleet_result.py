"""The result of a fleet batch (:class:`FleetResult`), its progress reports
(:class:`FleetProgress`), and the rows and alarms as the trends and ``alarms.json`` take
them."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.fleet import Alarm, AxisTrend, Observation, trended_parameters

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["FleetProgress", "FleetResult", "alarm_dict", "iso_utc", "observations"]


@dataclass(frozen=True)
class FleetProgress:
    """Where a batch is: ``total`` rows to analyse now, ``done`` of them (``failed``
    included), ``skipped`` (analysed by an earlier run of a resumed batch)."""

    total: int
    done: int = 0
    failed: int = 0
    skipped: int = 0
    stage: str = "analysing"


def iso_utc(seconds: float) -> str:
    """``2026-05-01T08:00:00.000000Z`` for a time in s since 1970."""
    return datetime.fromtimestamp(seconds, UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def alarm_dict(a: Alarm) -> dict[str, Any]:
    """One entry of ``alarms.json``."""
    return {"axis": a.axis, "parameter": a.parameter, "recording": a.recording,
            "start_time": iso_utc(a.start_time), "value": a.value, "baseline": a.baseline,
            "band": [a.band[0], a.band[1]]}


@dataclass(frozen=True)
class FleetResult:
    """The result of :func:`fleet`: ``table`` (pyarrow, one row per recording axis; the
    Parquet file), ``alarms`` (the entries of ``alarms.json``) and ``trends`` (per axis,
    every followed parameter with its baseline, band and points). Unpacks as
    ``table, alarms = ps.fleet(...)``; :meth:`to_dict` is the ``fleet --json`` summary.

    Example:
        >>> import pmsm_sysid as ps
        >>> result = ps.fleet("bags/paper_speed_coulomb", plant="plants/nominal.yaml",
        ...                   workers=1)
        >>> summary = result.to_dict()
        >>> summary["rows"], summary["failed"], summary["axes"][0]["state"]
        (1, 0, 'baseline')
        >>> print(result.summary())
          /pmsm: baseline, 1 recording(s)
    """

    table: pa.Table
    alarms: list[dict[str, Any]]
    trends: tuple[AxisTrend, ...]
    analysed: int
    """Rows analysed by this call."""
    failed: int
    """Of those, the rows with ``status: error``."""
    skipped: int
    """Recording axes already analysed in ``out`` (a resumed batch)."""
    duplicates: int
    """Recordings given twice (same content): analysed once."""
    out: Path | None = None
    files: dict[str, str] = field(default_factory=dict)

    def __iter__(self) -> Iterator[Any]:
        yield self.table
        yield self.alarms

    def axes(self) -> list[dict[str, Any]]:
        """Per axis: recordings, failed ones, the latest analysed, the state (``ok``,
        ``alarm``, ``baseline``, or ``failed`` when none was analysed) and what is in
        alarm since when."""
        status = self.table.select(["axis", "status"]).to_pylist()
        trends = {t.axis: t for t in self.trends}
        names = sorted({r["axis"] for r in status if r["axis"] is not None} | set(trends))
        out = []
        for axis in names:
            mine = [r for r in status if r["axis"] == axis]
            t = trends.get(axis)
            latest = max((q.start_time for p in (t.parameters if t else ()) for q in p.points),
                         default=None)
            out.append({
                "axis": axis, "recordings": len(mine),
                "failed": sum(1 for r in mine if r["status"] != "ok"),
                "state": t.state if t else "failed",
                "latest": None if latest is None else iso_utc(latest),
                "in_alarm": [{"parameter": p.parameter,
                              "since": iso_utc(p.alarms[-1].start_time) if p.alarms else None}
                             for p in (t.in_alarm if t else ())]})
        return out

    def to_dict(self) -> dict[str, Any]:
        """The ``fleet --json`` summary (plain JSON values)."""
        from ._json import plain

        out: dict[str, Any] = plain({
            "rows": self.table.num_rows, "analysed": self.analysed, "failed": self.failed,
            "skipped": self.skipped, "duplicates": self.duplicates, "axes": self.axes(),
            "alarms": self.alarms, "out": None if self.out is None else str(self.out),
            "files": self.files})
        return out

    def summary(self) -> str:
        """Lines for people: per axis its state, then the alarms."""
        lines = []
        for a in self.axes():
            what = "; ".join(f"{p['parameter']} out of band since {p['since']}"
                             for p in a["in_alarm"])
            lines.append(f"  {a['axis']}: {a['state']}, {a['recordings']} recording(s)"
                         + (f", {a['failed']} failed" if a["failed"] else "")
                         + (f": {what}" if what else ""))
        for al in self.alarms:
            lines.append(f"alarm: {al['axis']} {al['parameter']} = {al['value']:.5g} "
                         f"(baseline {al['baseline']:.5g}, band {al['band'][0]:.5g} .. "
                         f"{al['band'][1]:.5g}) at {al['recording']} ({al['start_time']})")
        return "\n".join(lines)


def observations(rows: Sequence[Mapping[str, Any]]) -> list[Observation]:
    """The analysed rows (status ok) as trend observations."""
    names = trended_parameters()
    out = []
    for r in rows:
        if r.get("status") != "ok" or r.get("start_time") is None:
            continue
        out.append(Observation(str(r.get("axis")), str(r.get("recording")),
                               float(r["start_time"]), {p: _num(r.get(p)) for p in names},
                               {p: _num(r.get(p + ".std")) for p in names}))
    return out


def _num(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None
