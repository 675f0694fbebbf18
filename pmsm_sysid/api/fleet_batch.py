"""A fleet of axes: :func:`fleet` analyses many recordings in parallel on Dask and follows
each axis's fitted plant over time, with drift alarms. Needs the ``[fleet]`` extra
(``dask[distributed]`` and ``pyarrow``)."""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..batch.cluster import CONNECT_TIMEOUT_S
from ..core.errors import OptionError
from ..core.fleet import AxisTrend, TrendOptions
from ..core.recording.spans import MAX_SAMPLES, MIN_SPAN, SPANS
from . import _checks
from .fleet_result import FleetProgress, FleetResult, alarm_dict, observations
from .fleet_row import MIN_DURATION_S, recording_row
from .simulation import PlantLike, resolve_plant

if TYPE_CHECKING:
    from dask.distributed import Client

    from ..batch.inputs import Unit
    from ..batch.store import Store

__all__ = ["FleetProgress", "FleetResult", "fleet"]

RecordingsLike = str | os.PathLike[str] | Sequence[str | os.PathLike[str]]
#: The table on disk is rewritten at most this often while rows come in (s); every row is
#: on disk (its own part file) the moment it is finished.
FLUSH_S = 5.0


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
               sim_namespace: str | None,
               options: dict[str, Any]) -> tuple[dict[str, Any], str, dict[str, Any]]:
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
    from .fleet_row import _options, _read

    opts = _options(options["alpha"], options["min_share"], options["max_samples"])
    ex = _read(sim, sim_namespace, None, opts, "simulated recording")
    check_identifiable(ex.parts, f"simulated recording {os.fspath(sim)}")
    digest = content_key(Path(sim))
    return ({"plant": None, "sim": os.fspath(sim), "sim_namespace": sim_namespace,
             "sim_sha256": digest}, f"the simulator's recording {os.fspath(sim)}",
            {"sim_sha256": digest, "sim_namespace": sim_namespace})


def _batch(plant: PlantLike, sim: str | os.PathLike[str] | None, sim_namespace: str | None,
           namespace: str | None, axis_from: str, numbers: tuple[float, float, float, int],
           trend: TrendOptions) -> _Batch:
    from ..batch.inputs import AXIS_FROM
    from ..validate import check_namespace

    for name, value in (("namespace", namespace), ("sim_namespace", sim_namespace)):
        if value is not None:
            check_namespace(value, name)
    _checks.choice("axis_from", axis_from, AXIS_FROM)
    min_duration, alpha, min_share, max_samples = numbers
    options = {"min_duration_s": _checks.positive("min_duration", min_duration),
               "alpha": _checks.fraction("alpha", alpha),
               "min_share": _checks.fraction("min_share", min_share),
               "max_samples": _checks.count("max_samples", max_samples, SPANS * MIN_SPAN)}
    reference, label, entry = _reference(plant, sim, sim_namespace, options)
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

    if client is None and scheduler_client is None and len(todo) == 1:
        # one recording axis to analyse: in this process; a local cluster would cost more
        # to start (a worker's imports alone: about 1.5 s of CPU) than the row (about 0.5 s)
        on_row(recording_row(todo[0].path, **todo[0].row_arguments(), **batch.row_options))
        return int(state["failed"])
    with ExitStack() as stack:
        # no more local workers than recordings to analyse: a worker started for nothing
        # costs its start (imports: about 1.5 s of CPU)
        c = client or scheduler_client or stack.enter_context(
            local_cluster(min(workers, len(todo))))
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
          max_samples: int = MAX_SAMPLES, baseline: int = 8, z: float = 4.0,
          min_change: float = 0.02,
          sim: str | os.PathLike[str] | None = None, sim_namespace: str | None = None,
          progress: Callable[[FleetProgress], None] | None = None,
          connect_timeout: float = CONNECT_TIMEOUT_S) -> FleetResult:
    """Fit the physical plant of many recordings, diagnose a reference plant on each, in
    parallel on Dask, and follow every axis's parameters over time with drift alarms.

    ``recordings``: paths, directories (searched for rosbag2 recordings) or glob patterns.
    ``plant``: the reference plant (a :class:`Plant`, a plant YAML path, None: nominal);
    or ``sim``, a recording of the user's own simulator as the reference (read with
    ``sim_namespace``; its plant is fitted once per worker and each recording is compared
    with it, as ``diagnose(None, real, sim=...)`` compares).
    Each axis of each recording becomes one row
    (:func:`pmsm_sysid.api.fleet_row.recording_row`): its fitted plant (:func:`fit_plant`)
    with standard errors and confidences, and the reference plant's fit before/after the
    diagnosed corrections (:func:`diagnose`); ``alpha``, ``min_share`` and ``max_samples``
    (a longer recording is used in ten spans spread evenly over it, of a bag only those are
    read) as in :func:`diagnose`; a recording shorter than ``min_duration`` s is a row with
    status error. Runs on ``client`` (a ``dask.distributed.Client`` of yours, left
    open), on the cluster whose scheduler is at ``scheduler`` (``tcp://HOST:PORT``; one that
    does not answer within ``connect_timeout`` s is refused before any work), or on a
    local cluster of ``workers`` processes (default: one per CPU; no more than there are
    recordings to analyse; a single recording axis to analyse is analysed in this process,
    without a cluster).

    With ``out`` (a new or empty directory, or one an earlier batch wrote) the table is kept
    on disk as it grows (``results.parquet``, readable at every moment), with
    ``alarms.json`` and ``index.html`` (the trends) at the end; ``resume=True`` skips every
    recording analysed there before (by content, not name) and retries the failed ones;
    ``force=True`` starts it again. Trends: per axis, each parameter against the median of
    its first ``baseline`` recordings, in a band from their spread and each recording's
    standard error at ``z`` standard deviations, never narrower than ``min_change`` of the
    baseline (:mod:`pmsm_sysid.core.fleet.trends` states the rule). ``progress`` is called
    with a :class:`FleetProgress` after each row.

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
    from ..batch.cluster import check_address
    from ..batch.inputs import expand
    from ..batch.store import check_out_dir

    _check_client(client, scheduler)
    if scheduler is not None:
        check_address(scheduler)
    timeout = _checks.positive("connect_timeout", connect_timeout)
    n = _default_workers() if workers is None else _checks.count("workers", workers, 1)
    batch = _batch(plant, sim, sim_namespace, namespace, axis_from,
                   (min_duration, alpha, min_share, max_samples),
                   TrendOptions(_checks.count("baseline", baseline, 3),
                                _checks.positive("z", z), _change(min_change)))
    out_path = None if out is None else Path(out)
    if resume and out_path is None:
        raise OptionError("resume needs out (the directory of the batch to resume)")
    resuming = out_path is not None and check_out_dir(out_path, resume=resume, force=force)
    paths = expand(_as_list(recordings))
    return _run(paths, batch, out_path, resuming, (client, scheduler, n, timeout),
                progress or (lambda p: None))


def _run(paths: Sequence[Path], batch: _Batch, out: Path | None, resuming: bool,
         where: tuple[Client | None, str | None, int, float],
         report: Callable[[FleetProgress], None]) -> FleetResult:
    """Connect (a scheduler answers, or no work is done), read the recordings, analyse
    what is not done yet, keep every row, then the trends."""
    from ..batch.cluster import check_workers, connect
    from ..batch.store import Store

    client, scheduler, n, timeout = where
    store = Store(out)
    with ExitStack() as stack:
        sched = None if scheduler is None else connect(scheduler, timeout)  # before any work
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
    return _finish(store, batch, out, (len(todo), failed, skipped, dup))


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
