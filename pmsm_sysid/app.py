"""Compose the package's nodes in one process: one SingleThreadedExecutor, spun here.

``build_pipeline(nodes=("sim", "identifier", "gfrf"), ...)`` creates the chosen nodes on one
rclpy Context (a private one from ``ROS_DOMAIN_ID``, or the caller's), adds them to one
executor and yields a :class:`Pipeline`; on exit everything is shut down in the safe order
(results flushed, recording finalised, executor, nodes, context). The nodes are ordinary
importable classes, so a user's own process can compose them the same way.

Clock: with ``clock="wall"`` the sim node paces itself to real time. With ``clock="sim"``
and the identifier in the same process, the pipeline steps the simulator itself, in bursts
of up to ``hop`` samples, whenever the identifier has taken what was published and no window
waits for a fit (back-pressure), so the run is as fast as identification allows, loses nothing and
skips no window (deterministic: same plant and seed, same models); while a window waits, the
executor sleeps until the fitting thread takes it (it triggers a guard condition of the
identifier's, :meth:`.IdentifierNode.wake_on_window`), not polling. The fitting thread takes
the next window while the previous one is still being fitted (it hands two at most to the
worker process), so the worker goes from one fit to the next without waiting for the
hand-over between them; without an identifier
here, the sim node runs at ``rate`` x real time on its own timer. With ``record``, the
recorder runs in a process of its own (:mod:`.nodes.recorder_process`), started after the
nodes (a sim elsewhere that waits for a subscriber finds the identifier first); the sim here
starts once the recorder's subscriptions are matched, and under the sim clock it also waits for the
recorder (its progress is read from shared memory), so the bag holds every sample.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from .core.errors import PmsmSysidError
from .core.physics.plant import Plant
from .pipeline_nodes import DEFAULT_NODES, parse_nodes
from .pipeline_start import start_recorder, wait_for_recorder, wait_until_matched
from .pipeline_summary import pipeline_summary
from .topics import DEFAULT_NAMESPACE

BACKLOG = 200  # samples the sim may run ahead of the identifier under back-pressure
RECORD_BACKLOG = 2000  # ... and ahead of the recorder (it queues 10000 per topic)
MATCH_S = 30.0  # how long to wait for the recorder process to match the publishers
#: While the stepped sim waits for the recorder (or the GFRF node), how long the executor may
#: block between looks (rather than spin at full CPU beside the processes it waits for).
BUSY_WAIT_S = 0.002
#: ... and while it waits for a fit: the fitting thread wakes the executor as it takes the
#: waiting window, so this is only the longest sleep between looks.
FIT_WAIT_S = 0.05
SETTLE_S = 5.0  # after the sim's last sample, how long the identifier may still take
DIAGNOSE_WAIT_S = 300.0  # at the end, how long an outstanding diagnosis may still take


def overrides(values: Mapping[str, Any] | None) -> list[Parameter]:
    return [Parameter(k, value=v)  # type: ignore[no-untyped-call]
            for k, v in (values or {}).items()]


@dataclass
class Pipeline:
    """The running nodes of one process and the loop that spins them."""

    context: Context
    executor: SingleThreadedExecutor
    nodes: dict[str, Any]
    clock: str
    stop: threading.Event = field(default_factory=threading.Event)
    recorder: Any = None
    record_result: dict[str, Any] | None = None
    record_error: str | None = None
    gfrf_every_model: bool = False
    started: float = field(default_factory=time.monotonic)

    @property
    def sim(self) -> Any:
        return self.nodes.get("sim")

    @property
    def identifier(self) -> Any:
        return self.nodes.get("identifier")

    @property
    def gfrf(self) -> Any:
        return self.nodes.get("gfrf")

    @property
    def diagnose(self) -> Any:
        return self.nodes.get("diagnose")

    @property
    def consumers(self) -> list[Any]:
        """The engines of this process that take the sim's samples (identifier, diagnosis)."""
        return [n.engine for n in (self.identifier, self.diagnose) if n is not None]

    @property
    def stepped(self) -> bool:
        """True when this pipeline steps the simulator itself (sim clock, back-pressure)."""
        return self.clock == "sim" and self.sim is not None and bool(self.consumers)

    def run(self, duration_s: float | None = None,
            until: Callable[[], bool] | None = None) -> None:
        """Spin until ``until()``, the stop event, or ``duration_s`` more seconds of data:
        with the sim node here, until it has published that many more samples (it stops
        there, ``max_samples``) and the identifier here has taken them; without it, for
        ``duration_s`` wall-clock seconds. None = no limit."""
        limit = None
        if duration_s is not None and self.sim is not None:
            limit = self.sim.published + round(duration_s * self.sim.fs)
            if not self.stepped:
                self.sim.set_parameters([Parameter(  # type: ignore[no-untyped-call]
                    "max_samples", value=limit)])
            duration_s = None
        deadline = None if duration_s is None else time.monotonic() + duration_s
        settle = 0.0
        while not self.stop.is_set() and self.context.ok():
            if until is not None and until():
                return
            if deadline is not None and time.monotonic() >= deadline:
                return
            if limit is not None and self.sim.published >= limit and self._caught_up():
                return
            if limit is not None and self.sim.published >= limit:
                settle = settle or time.monotonic() + SETTLE_S
                if time.monotonic() > settle:
                    return  # what has not arrived by now is counted missing, not awaited
            wait = 0.05
            if self.stepped:
                wait = self._step_sim(limit)
                self._take_pending()
            self.executor.spin_once(timeout_sec=wait)

    def _take_pending(self, all_of_it: bool = False) -> None:
        """The consumers here take the samples just published, without a round of the
        executor each (its wait set costs more than a burst's messages); ``all_of_it``:
        until none is left (one call takes a bounded burst)."""
        while True:
            before = [e.samples_received for e in self.consumers]
            for node in (self.identifier, self.diagnose):
                if node is not None:
                    node.take_pending()
            if not all_of_it or [e.samples_received for e in self.consumers] == before:
                return

    def _caught_up(self) -> bool:
        return all(e.samples_received >= self.sim.published for e in self.consumers)

    def _gfrf_caught_up(self) -> bool:
        """The identifier has fitted and published everything, and the GFRF node has
        received and analysed (or skipped) every model published."""
        ident, g = self.identifier, self.gfrf
        return bool(ident.engine.idle and g.received >= ident.models_published
                    and g.worker.stats.processed + g.queue.skipped >= g.received)

    def _step_sim(self, limit: int | None) -> float:
        """Publish the next burst unless the identifier, the diagnosis (or the recorder) is
        behind (the GFRF node analyses the newest models and counts what it skips; with
        ``gfrf_every_model`` the sim waits for it too). At most ``hop`` samples are in
        flight (published, not yet taken by the identifier or the diagnosis) and none is
        published while a window or a span waits for its worker, so at most one becomes due
        per burst and none is ever skipped. Returns how long the executor may then wait:
        0 unless a consumer is behind; while only a fit is awaited, until the fitting
        thread takes the window (it wakes the executor, :meth:`wake_on_window`)."""
        sim, engines = self.sim, self.consumers
        backlog = sim.published - min(e.samples_received for e in engines)
        fitting = any(e.windows_waiting > 0 for e in engines)
        behind = False
        if self.gfrf_every_model and self.gfrf is not None and self.identifier is not None:
            behind = not self._gfrf_caught_up()
        if self.recorder is not None:
            behind = behind or sim.published - self.recorder.samples_recorded >= RECORD_BACKLOG
        room = min(BACKLOG, *(e.config.hop for e in engines)) - backlog
        if limit is not None:
            room = min(room, limit - sim.published)
        if self.identifier is not None:  # a pause of the sim here is not stale input
            self.identifier.hold_input(fitting or behind)
        if behind:
            return BUSY_WAIT_S
        if fitting:
            return FIT_WAIT_S
        if room > 0:
            sim.step(room)
        return 0.0

    def finish(self, timeout_s: float = 30.0) -> None:
        """Let other processes acknowledge the sim's last samples, fit what is queued and
        publish it, let the GFRF node analyse the last models, and let this process's
        collector receive the results (each step bounded)."""
        ident, g = self.identifier, self.gfrf
        if self.sim is not None:  # reliable delivery of the last samples to other processes
            from rclpy.duration import Duration

            # the run is over (its duration, a signal, the caller's condition): the motor
            # publishes nothing more, or every wait below would chase samples published
            # while it waits (beside busy processes a SIGTERM'd run went on for 30 s)
            self.sim.stop_timer()
            for pub in self.sim.publishers:
                pub.wait_for_all_acked(Duration(seconds=min(timeout_s, 2.0)))
            # what it published before it stopped is taken now, before the windows are
            # flushed: a wall-clock run stops with a burst still in the queues (the executor
            # hands a burst over a round after it is published)
            self._take_pending(all_of_it=True)
        if ident is not None:
            if self.sim is not None:
                ident.end_of_input()
            ident.engine.flush()
            ident.engine.wait_idle(timeout_s)
            ident.publish_results()
        if g is not None:
            want = ident.models_published if ident is not None else g.received
            self._spin_while(lambda: not (g.received >= want and g.worker.stats.processed
                                          + g.queue.skipped >= g.received), timeout_s)
            g.publish_results()
        self.finish_diagnosis(max(timeout_s, DIAGNOSE_WAIT_S))
        col = self.nodes.get("collector")
        if col is not None:
            models = ident.models_published if ident is not None else 0
            ridges = g.published if g is not None else 0
            diagnoses = self.diagnose.published if self.diagnose is not None else 0
            self._spin_while(lambda: col.counts["model"] < models
                             or col.counts["ridges"] < ridges
                             or col.counts["diagnosis"] < diagnoses, min(timeout_s, 5.0))
        self.executor.spin_once(timeout_sec=0.05)
        if self.recorder is not None:
            self.finish_recording(timeout_s)

    def finish_diagnosis(self, timeout_s: float = DIAGNOSE_WAIT_S) -> None:
        """Diagnose a span the last samples completed, wait for the diagnosis in progress
        (at most ``timeout_s``) and publish what is finished."""
        d = self.diagnose
        if d is None:
            return
        d.engine.flush()
        d.engine.wait_idle(timeout_s)
        d.publish_results()

    def finish_recording(self, timeout_s: float = 30.0) -> None:
        """Wait until the recorder holds every sample published (or received) here and has
        acknowledged every message published here (each bounded by ``timeout_s``), then let
        it take them all, finalise the bag and report its counts (``record_result``)."""
        from rclpy.duration import Duration

        rec = self.recorder
        want = (self.sim.published if self.sim is not None else
                self.identifier.engine.samples_received if self.identifier is not None else 0)
        # the input topics that came (a speed derived from position never does)
        came = (rec.inputs if self.sim is not None or self.identifier is None
                else list(self.identifier.input_report().arrived))
        self._spin_while(lambda: rec.alive and rec.samples_recorded_of(came) < want, timeout_s)
        for node in self.nodes.values():
            for pub in node.publishers:
                if pub.topic_name in rec.topics:
                    pub.wait_for_all_acked(Duration(seconds=min(timeout_s, 5.0)))
        try:
            self.record_result = self.recorder.stop(timeout_s)
        except PmsmSysidError as exc:  # reported in the summary, not hidden
            self.record_error = str(exc)

    def _spin_while(self, busy: Callable[[], bool], timeout_s: float) -> None:
        t_end = time.monotonic() + timeout_s
        while busy() and time.monotonic() < t_end and self.context.ok():
            self.executor.spin_once(timeout_sec=0.02)

    def summary(self) -> dict[str, Any]:
        """The ``run --json`` summary (the documented keys plus per-node details)."""
        return pipeline_summary(self)


def _make_node(name: str, ctx: Context, opts: dict[str, Any]) -> Node:
    if name == "sim":
        from .nodes.sim_node import MotorSimNode

        return MotorSimNode(context=ctx, plant=opts["plant"], excitation=opts["excitation"],
                            seed=opts["seed"], namespace=opts["namespace"],
                            clock=opts["clock"], rate=opts["rate"],
                            parameter_overrides=overrides(opts["sim_params"]))
    if name == "identifier":
        from .nodes.identifier_node import IdentifierNode

        return IdentifierNode(context=ctx, namespace=opts["namespace"],
                              parameter_overrides=overrides(opts["identifier_params"]))
    if name == "diagnose":
        from .nodes.diagnosis_node import DiagnosisNode

        return DiagnosisNode(context=ctx, namespace=opts["namespace"],
                             parameter_overrides=overrides(opts["diagnose_params"]))
    from .nodes.gfrf_node import GfrfNode

    n_outputs = len((opts["identifier_params"] or {}).get("outputs", ("speed", "position")))
    params = {"queue_size": max(2, n_outputs), **(opts["gfrf_params"] or {})}
    return GfrfNode(context=ctx, namespace=opts["namespace"],
                    parameter_overrides=overrides(params))


def _make_checked(name: str, ctx: Context, opts: dict[str, Any]) -> Node:
    """``_make_node`` with parameter problems turned into one clear PmsmSysidError."""
    from rclpy.exceptions import ParameterException

    try:
        node = _make_node(name, ctx, opts)
    except ParameterException as exc:
        raise PmsmSysidError(f"{name} node: {exc}") from exc
    given = opts.get(f"{name}_params") or {}
    unknown = sorted(k for k in given if not node.has_parameter(k))
    if unknown:
        node.destroy_node()  # type: ignore[no-untyped-call]
        raise PmsmSysidError(f"{name} node has no parameter(s) {', '.join(unknown)}")
    return node


@contextmanager
def build_pipeline(
    nodes: Sequence[str] = DEFAULT_NODES, *, plant: Plant | None = None,
    excitation: str = "paper-speed", seed: int = 0, clock: str = "wall", rate: float = 1.0,
    namespace: str = DEFAULT_NAMESPACE, record: str | None = None,
    identifier_params: Mapping[str, Any] | None = None,
    sim_params: Mapping[str, Any] | None = None, gfrf_params: Mapping[str, Any] | None = None,
    diagnose_params: Mapping[str, Any] | None = None, context: Context | None = None,
    domain_id: int | None = None, wait_s: float = 0.0,
    subscribers: int = 1, ros_args: Sequence[str] | None = None,
    gfrf_every_model: bool = False,
) -> Iterator[Pipeline]:
    """Create ``nodes`` in one process and yield the :class:`Pipeline` (see module doc).

    ``wait_s``: with the sim node but no identifier here, wait up to that long for another
    process to subscribe to the input topics before the sim starts (0 = start at once);
    ``subscribers``: how many subscribers per input topic to wait for (default 1).
    ``ros_args``: ROS arguments (``--ros-args --params-file F -p name:=value -r a:=b``) for
    the private context (:mod:`.rosargs`); not with a caller's ``context``, whose own
    arguments apply. The keyword arguments here win over them.
    ``gfrf_every_model``: under the stepped sim clock, also wait for the GFRF node, so it
    analyses every model (slower: an analysis costs more than a fit).
    ``diagnose_params``: the diagnosis node's parameters (``plant_file`` or
    ``sim_namespace``, ``period_s``, ``span_s``, ...); under the stepped sim clock the sim
    also waits for it, so no span is skipped.
    """
    from .rosutil import check_namespace, ros_session

    namespace = check_namespace(namespace)
    # the input subscribers last (the identifier last of all): their subscriptions appear
    # just before the executor spins
    names = tuple(sorted(parse_nodes(nodes),
                         key=lambda n: (n == "identifier", n == "diagnose")))
    if clock not in ("wall", "sim"):
        raise PmsmSysidError(f"clock must be 'wall' or 'sim', got '{clock}'")
    opts = {"plant": plant, "excitation": excitation, "seed": seed, "namespace": namespace,
            "clock": clock, "rate": rate if clock == "sim" else 1.0,
            "identifier_params": identifier_params, "sim_params": sim_params,
            "gfrf_params": gfrf_params, "diagnose_params": diagnose_params}
    if ros_args and context is not None:
        raise PmsmSysidError("ros_args apply to a context this pipeline creates, not to a "
                             "given one (pass them to rclpy.init of that context)")
    with _context(context, domain_id, ros_session, ros_args, namespace) as (ctx, executor):
        made: dict[str, Any] = {}
        pipe = Pipeline(ctx, executor, made, clock, gfrf_every_model=gfrf_every_model)
        try:
            if {"identifier", "gfrf", "diagnose"} & set(names):
                from .nodes.collector import ResultCollector

                made["collector"] = ResultCollector(context=ctx, namespace=namespace)
                executor.add_node(made["collector"])
            for name in names:
                made[name] = _make_checked(name, ctx, opts)
                executor.add_node(made[name])
            if record is not None:  # the sim here is held until it records
                pipe.recorder = start_recorder(ctx, record, namespace, pipe.identifier)
                wait_for_recorder(pipe, MATCH_S)
            if pipe.stepped:
                pipe.sim.stop_timer()  # stepped by the pipeline (back-pressure)
                for node in (pipe.identifier, pipe.diagnose):
                    if node is not None:
                        node.wake_on_window()
                if pipe.identifier is not None:  # the worker never waits for a hand-over
                    pipe.identifier.engine.hand_over_ahead(2)
            elif pipe.sim is not None and wait_s > 0 and "identifier" not in names:
                wait_until_matched(pipe.sim, executor, wait_s, subscribers)
            pipe.started = time.monotonic()
            if pipe.identifier is not None:
                pipe.identifier.restart_input_clock()
            yield pipe
        finally:
            _shutdown(pipe)


@contextmanager
def _context(context: Context | None, domain_id: int | None, session: Any,
             ros_args: Sequence[str] | None = None, namespace: str = DEFAULT_NAMESPACE,
             ) -> Iterator[tuple[Context, SingleThreadedExecutor]]:
    if context is None:
        from .rosargs import prepared

        with prepared(ros_args or [], namespace) as args, session(domain_id, args) as s:
            yield s.context, s.executor
        return
    executor = SingleThreadedExecutor(context=context)
    try:
        yield context, executor
    finally:
        executor.shutdown(timeout_sec=2.0)


def _shutdown(pipe: Pipeline) -> None:
    """Finalise the recording first (it must survive anything after), then the nodes."""
    try:
        if pipe.recorder is not None:
            pipe.recorder.close()
    finally:
        for node in pipe.nodes.values():
            pipe.executor.remove_node(node)
            node.destroy_node()

