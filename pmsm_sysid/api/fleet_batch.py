"""A fleet of axes: :func:`fleet` analyses many recordings in parallel on Dask and follows
each axis's fitted plant over time, with drift alarms. Needs the ``[fleet]`` extra
(``dask[distributed]`` and ``pyarrow``)."""

from __future__ import annotations

import hashlib
import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.errors import OptionError
from ..core.fleet import Alarm, AxisTrend, Observation, TrendOptions, trended_parameters
from . import _checks
from .fleet_row import MIN_DURATION_S, recording_row
from .simulation import PlantLike, resolve_plant

if TYPE_CHECKING:
    import pyarrow as pa
    from dask.distributed import Client

    from ..batch.inputs import Unit
    from ..batch.store import Store

RecordingsLike = str | os.PathLike[str] | Sequence[str | os.PathLike[str]]
#: The table on disk is rewritten at most this often while rows come in (s); every row is
#: on disk (its own part file) the moment it is finished.
FLUSH_S = 5.0


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
    ``table, alarms = ps.fleet(...)``; :meth:`to_dict` is the ``fleet --json`` summary."""

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
        """Per axis: recordings, failed ones, the latest, the state and what is in alarm."""
        status = self.table.select(["axis", "status", "start_time"]).to_pylist()
        out = []
        for t in self.trends:
            mine = [r for r in status if r["axis"] == t.axis]
            latest = max((p.start_time for p in (t.parameters[0].points
                                                 if t.parameters else ())), default=None)
            out.append({
                "axis": t.axis, "recordings": len(mine),
                "failed": sum(1 for r in mine if r["status"] != "ok"), "state": t.state,
                "latest": None if latest is None else iso_utc(latest),
                "in_alarm": [{"parameter": p.parameter,
                              "since": iso_utc(p.alarms[-1].start_time) if p.alarms else None}
                             for p in t.in_alarm]})
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


def _as_list(recordings: RecordingsLike) -> list[str]:
    if isinstance(recordings, (str, os.PathLike)):
        return [os.fspath(recordings)]
    if not isinstance(recordings, Sequence):
        raise OptionError("recordings must be a path, a glob pattern or a list of them, got "
                          f"{type(recordings).__name__}")
    return [os.fspath(r) for r in recordings]


@dataclass(frozen=True)
class _Batch:
    """Checked options of one call."""

    row_options: dict[str, Any]
    trend: TrendOptions
    manifest: dict[str, Any]
    namespace: str | None
    axis_from: str


def _reference(plant: PlantLike, sim: str | os.PathLike[str] | None,
               sim_namespace: str | None) -> tuple[dict[str, Any], str, dict[str, Any]]:
    """(row options, label, manifest entry) of the reference: a plant, or a simulator's
    recording (read and checked here, before any work: it must identify a plant)."""
    if sim is None:
        model, label = resolve_plant(plant)
        digest = hashlib.sha256(model.to_yaml().encode()).hexdigest()
        return {"plant": model}, label, {"plant_sha256": digest}
    if plant is not None:
        raise OptionError("give either a plant or a recording of the simulator (sim), not "
                          "both")
    from ..batch.inputs import content_key
    from ..core.plantfit.physical import check_identifiable
    from ..core.selection.datacheck import check_sampling
    from .diagnosis import _recording

    rec = _recording(sim, "sim", sim_namespace)
    check_sampling(rec.t, rec.sample_rate_hz, f"recording {sim}")
    check_identifiable(rec, f"recording {sim}")
    digest = content_key(Path(sim))
    return ({"plant": None, "sim": os.fspath(sim), "sim_namespace": sim_namespace,
             "sim_sha256": digest}, f"the simulator's recording {os.fspath(sim)}",
            {"sim_sha256": digest, "sim_namespace": sim_namespace})


def _batch(plant: PlantLike, sim: str | os.PathLike[str] | None, sim_namespace: str | None,
           namespace: str | None, axis_from: str, min_duration: float, alpha: float,
           min_share: float, trend: TrendOptions) -> _Batch:
    from ..batch.inputs import AXIS_FROM
    from ..validate import check_namespace

    for name, value in (("namespace", namespace), ("sim_namespace", sim_namespace)):
        if value is not None:
            check_namespace(value, name)
    _checks.choice("axis_from", axis_from, AXIS_FROM)
    options = {"min_duration_s": _checks.positive("min_duration", min_duration),
               "alpha": _checks.fraction("alpha", alpha),
               "min_share": _checks.fraction("min_share", min_share)}
    reference, label, entry = _reference(plant, sim, sim_namespace)
    manifest = {"tool": "pmsm-sysid fleet", "plant": label, "reference": entry,
                "options": {**options, "namespace": namespace, "axis_from": axis_from}}
    return _Batch({**reference, **options}, trend, manifest, namespace, axis_from)


def _todo(units: Sequence[Unit], done: set[str]) -> tuple[list[Unit], int, int]:
    """(units to analyse, how many were done already, how many repeat a unit's content)."""
    seen: set[str] = set()
    todo, skipped, dup = [], 0, 0
    for u in units:
        if u.key in seen:
            dup += 1
            continue
        seen.add(u.key)
        if u.key in done:
            skipped += 1
        else:
            todo.append(u)
    return todo, skipped, dup


def _failure_row(unit: Unit, exc: BaseException) -> dict[str, Any]:
    from ..core.fleet import empty_row

    row = empty_row()
    row.update(recording=unit.path, axis=unit.axis, status="error",
               namespace=unit.namespace, joint=unit.joint, content_sha256=unit.content,
               analysed_at=time.time(),
               error=" ".join(f"{unit.path}: the worker analysing it failed "
                              f"({type(exc).__name__}: {exc})".split()))
    return row


def _analyse(client: Client | None, scheduler_client: Client | None, workers: int,
             todo: list[Unit], batch: _Batch, store: Store,
             report: Callable[[FleetProgress], None], progress: FleetProgress) -> int:
    """Run the units on the given client, the scheduler's, or a local cluster; return how
    many failed."""
    from ..batch.cluster import local_cluster, run

    state = {"done": 0, "failed": 0, "flushed": time.monotonic()}

    def on_row(row: dict[str, Any]) -> None:
        store.add(row)
        state["done"] += 1
        state["failed"] += row.get("status") != "ok"
        if time.monotonic() - state["flushed"] >= FLUSH_S:
            store.flush()
            state["flushed"] = time.monotonic()
        report(FleetProgress(progress.total, int(state["done"]), int(state["failed"]),
                             progress.skipped))

    with ExitStack() as stack:
        c = client or scheduler_client or stack.enter_context(local_cluster(workers))
        run(c, todo, recording_row, batch.row_options, on_row, _failure_row)
    return int(state["failed"])


def _outputs(out: Path, trends: tuple[AxisTrend, ...], alarms: list[dict[str, Any]],
             rows: Sequence[Mapping[str, Any]], title: str,
             options: TrendOptions) -> dict[str, str]:
    """alarms.json and the page of trends, beside the table."""
    import json

    from ..batch.store import ALARMS, PAGE, RESULTS
    from ..report.fleet import write_fleet_report
    from ..validate import atomic_write_text
    from ._json import plain

    atomic_write_text(out / ALARMS, json.dumps(plain(alarms), indent=2) + "\n", "--out")
    write_fleet_report(out, trends, rows, title=title, options=options)
    return {"table": str(out / RESULTS), "alarms": str(out / ALARMS), "page": str(out / PAGE)}


def _change(value: Any) -> float:
    """min_change: a number in [0, 1)."""
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"min_change must be a number in [0, 1), got {value!r}") from exc
    if not 0 <= x < 1:
        raise OptionError(f"min_change must be a number in [0, 1), got {value!r}")
    return x


def _default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _check_client(client: Any, scheduler: str | None) -> None:
    from dask.distributed import Client

    if client is not None and not isinstance(client, Client):
        raise OptionError(f"client must be a dask.distributed.Client, got "
                          f"{type(client).__name__}")
    if client is not None and scheduler is not None:
        raise OptionError("give client or scheduler, not both")


def fleet(recordings: RecordingsLike, plant: PlantLike = None, *, client: Any = None,
          scheduler: str | None = None, workers: int | None = None,
          out: str | os.PathLike[str] | None = None, resume: bool = False, force: bool = False,
          namespace: str | None = None, axis_from: str = "topic",
          min_duration: float = MIN_DURATION_S, alpha: float = 1e-3, min_share: float = 0.01,
          baseline: int = 8, z: float = 4.0, min_change: float = 0.02,
          sim: str | os.PathLike[str] | None = None, sim_namespace: str | None = None,
          progress: Callable[[FleetProgress], None] | None = None) -> FleetResult:
    """Fit the physical plant of many recordings, diagnose a reference plant on each, in
    parallel on Dask, and follow every axis's parameters over time with drift alarms.

    ``recordings``: paths, directories (searched for rosbag2 recordings) or glob patterns.
    ``plant``: the reference plant (a :class:`Plant`, a plant YAML path, None: nominal);
    or ``sim``, a recording of the user's own simulator as the reference (read with
    ``sim_namespace``; its plant is fitted once per worker and each recording is compared
    with it, as ``diagnose(None, real, sim=...)`` compares).
    Each axis of each recording becomes one row (:func:`pmsm_sysid.api.fleet_row.
    recording_row`): its fitted plant (:func:`fit_plant`) with standard errors and
    confidences, and the reference plant's fit before/after the diagnosed corrections
    (:func:`diagnose`). Runs on ``client`` (a ``dask.distributed.Client`` of yours, left
    open), on the cluster whose scheduler is at ``scheduler`` (``tcp://HOST:PORT``), or on a
    local cluster of ``workers`` processes (default: one per CPU).

    With ``out`` (a new or empty directory, or one an earlier batch wrote) the table is kept
    on disk as it grows (``results.parquet``, readable at every moment), with
    ``alarms.json`` and ``index.html`` (the trends) at the end; ``resume=True`` skips every
    recording analysed there before (by content, not name) and retries the failed ones;
    ``force=True`` starts it again. Trends: per axis, each parameter against the median of
    its first ``baseline`` recordings, in a band from their spread and each recording's
    standard error at ``z`` standard deviations, never narrower than ``min_change`` of the
    baseline (:mod:`pmsm_sysid.core.fleet.trends` states the rule). ``progress`` is called with a
    :class:`FleetProgress` after each row.

    Returns a :class:`FleetResult`; ``table, alarms = ps.fleet(...)`` unpacks it.

    Example:
        >>> import pmsm_sysid as ps
        >>> table, alarms = ps.fleet(["bags/paper_speed_nominal", "bags/paper_speed_coulomb"],
        ...                          plant="plants/nominal.yaml", workers=1)
        >>> table.column("recording").to_pylist()  # by axis, start time, name
        ['bags/paper_speed_coulomb', 'bags/paper_speed_nominal']
        >>> table.column("status").to_pylist(), table.column("axis").to_pylist()
        (['ok', 'ok'], ['/pmsm', '/pmsm'])
        >>> table.column("coulomb_friction.amplitude_n").to_pylist()  # doctest: +ELLIPSIS
        [4.0..., None]
        >>> alarms  # two recordings are no baseline yet
        []
    """
    from ..batch.cluster import require_extra

    require_extra()  # before anything imports Dask or pyarrow
    from ..batch.cluster import check_address, check_workers, connect
    from ..batch.inputs import expand
    from ..batch.store import Store, check_out_dir

    _check_client(client, scheduler)
    if scheduler is not None:
        check_address(scheduler)
    n = _default_workers() if workers is None else _checks.count("workers", workers, 1)
    batch = _batch(plant, sim, sim_namespace, namespace, axis_from, min_duration, alpha,
                   min_share,
                   TrendOptions(_checks.count("baseline", baseline, 3),
                                _checks.positive("z", z), _change(min_change)))
    out_path = None if out is None else Path(out)
    if resume and out_path is None:
        raise OptionError("resume needs out (the directory of the batch to resume)")
    resuming = out_path is not None and check_out_dir(out_path, resume=resume, force=force)
    paths = expand(_as_list(recordings))
    report = progress or (lambda p: None)
    store = Store(out_path)
    with ExitStack() as stack:
        sched = None if scheduler is None else connect(scheduler)  # before any work
        if sched is not None:
            stack.callback(sched.close)
        if client is not None:
            check_workers(client, "client")
        units = _units(paths, batch, report)
        store.open(batch.manifest, resume=resuming)
        todo, skipped, dup = _todo(units, store.done())
        report(FleetProgress(len(todo), skipped=skipped))
        failed = 0
        try:
            if todo:
                failed = _analyse(client, sched, n, todo, batch, store, report,
                                  FleetProgress(len(todo), skipped=skipped))
        finally:
            store.flush()
        store.close()
    return _finish(store, batch, out_path, (len(todo), failed, skipped, dup))


def _units(paths: Sequence[Path], batch: _Batch,
           report: Callable[[FleetProgress], None]) -> list[Unit]:
    """Every recording's axes and content keys (reads every recording's files once)."""
    from ..batch.inputs import units_of

    units: list[Unit] = []
    for i, p in enumerate(paths):
        report(FleetProgress(len(paths), done=i, stage="reading recordings"))
        units += units_of(p, batch.namespace, batch.axis_from)
    return units


def _finish(store: Store, batch: _Batch, out: Path | None,
            counts: tuple[int, int, int, int]) -> FleetResult:
    from ..core.fleet import fleet_alarms, fleet_trends

    rows = list(store.rows.values())
    trends = fleet_trends(observations(rows), batch.trend)
    alarms = [alarm_dict(a) for a in fleet_alarms(trends)]
    files = {} if out is None else _outputs(
        out, trends, alarms, rows, f"A fleet of axes against {batch.manifest['plant']}",
        batch.trend)
    return FleetResult(store.table(), alarms, trends, *counts, out=out, files=files)
