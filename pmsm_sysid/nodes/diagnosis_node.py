"""DiagnosisNode: the live sim-to-real diagnosis of a running drive.

Lives in the pipeline's namespace ``<ns>`` (node ``<ns>/pmsm_diagnose``; topic names
relative to it). Subscribes to ``<ns>/thrust|speed|position`` and aligns them exactly as the
identifier does (:class:`~pmsm_sysid.core.online.engine.OnlineEngine`: stamp alignment,
speed derived from position when none is published, a window ring cut on the absolute
sample grid). Every ``period_s`` seconds of data (stamp time, so simulated seconds under a
simulated clock) the latest ``span_s`` seconds become one diagnosis, run by ``ps.diagnose``
in a worker process of the node's own (parameter ``worker``), handed over through a
latest-wins queue: a span replaced before the worker took it is counted as skipped, never
queued without bound. The reference is a plant file (``plant_file``) or, with
``sim_namespace``, a simulator publishing its own thrust, speed and position beside the
drive: its latest span is aligned the same way and the drive's span is diagnosed against it.
Held-out data: diagnose's own split (the last 30 % of the span; see
:mod:`.diagnosis_work`). A timer publishes finished diagnoses from the executor thread:

* ``<ns>/diagnosis`` (std_msgs/String): the diagnose JSON of the span plus ``window``,
  ``reference``, ``held_out``, ``diagnosis_cpu_s`` and ``counts`` (diagnoses run, skipped,
  failed so far);
* ``<ns>/stats/diagnosis/<effect>/<param>`` (std_msgs/Float64, NaN while not named),
  ``.../effects_named``, ``.../unexplained`` (Int32) and ``.../force_nrmse_before|after``;
* its health on ``/diagnostics``: WARN, with the effects in the message, while the latest
  diagnosis finds physics the reference lacks, and when a diagnosis failed or spans were
  skipped.

``period_s``, ``span_s``, ``alpha``, ``min_share``, ``replay`` and ``gfrf`` may change while
it runs (from the next span on).
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.context import Context
from rclpy.guard_condition import GuardCondition
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String

from .. import diagnosed
from ..clocktext import stamp_text
from ..core.errors import DataError
from ..core.frequency.analysis import json_safe
from ..core.online.engine import EngineConfig, OnlineEngine, WindowError
from ..core.online.spans import LatestSpan, SpanSizer
from ..core.online.windows import Window
from ..core.online.workerproc import ProcessWorker
from ..topics import DEFAULT_NAMESPACE, DIAGNOSIS, normalize_namespace
from .diagnosis_work import DiagnoseJob, LiveDiagnoser
from .health import HealthPublisher, diagnose_health
from .intake import InputIntake
from .numbers import NumberPublisher
from .params import DIAGNOSE_SPECS, apply_or_refuse, declare_all

DEFAULTS: dict[str, Any] = {
    "plant_file": "", "sim_namespace": "", "period_s": 10.0, "span_s": 30.0,
    "alpha": 1e-3, "min_share": 0.01, "replay": True, "gfrf": False, "queue_size": 1,
    "sample_rate_hz": 0.0, "tolerance_s": 0.0, "speed_source": "auto",
    "publish_period_s": 0.1, "worker": "process",
}
WORKERS = ("process", "thread")
PROVISIONAL_HZ = 500.0  # sizes the ring until the stamps tell the rate
NICE = 5  # diagnoses yield the CPU to the fits and the data path (a span may be skipped)
OPTIONS = ("alpha", "min_share", "replay", "gfrf")


def reference(p: dict[str, Any], namespace: str) -> tuple[Any, str]:
    """(the plant, its file) or (None, the simulator's namespace): DataError unless exactly
    one of ``plant_file`` and ``sim_namespace`` is given and it is usable."""
    from ..core.physics.plant import load_plant
    from ..validate import check_namespace

    plant_file, sim_ns = str(p["plant_file"]).strip(), str(p["sim_namespace"]).strip()
    if bool(plant_file) == bool(sim_ns):
        raise DataError("the diagnose node needs exactly one reference: plant_file (a plant "
                        "file) or sim_namespace (a simulator's namespace)")
    if plant_file:
        return load_plant(plant_file), plant_file
    ns = normalize_namespace(check_namespace(sim_ns, "sim_namespace"))
    if ns == normalize_namespace(namespace):
        raise DataError(f"sim_namespace {ns} is the drive's own namespace: the simulator must "
                        "publish under another one")
    return None, ns


def worker(plant: Any, label: str, where: str) -> Callable[[DiagnoseJob], dict[str, Any]]:
    """The diagnoser in a worker process of its own, or called in the engine's thread."""
    if where not in WORKERS:
        raise DataError(f"parameter worker must be 'process' or 'thread' (got '{where}')")
    if where == "thread":
        return LiveDiagnoser(plant, label)
    return ProcessWorker[DiagnoseJob, dict[str, Any]](LiveDiagnoser, (plant, label),
                                                       nice=NICE)


class SpanDiagnosis:
    """``process(window)`` of the engine: the window and the current options as a job for
    the worker (CPU of the worker process in ``cpu_s``; ``close`` ends it). ``on_take`` (if
    set) is called as each span is taken, in the engine's thread."""

    def __init__(self, work: Callable[[DiagnoseJob], dict[str, Any]],
                 job: Callable[[Window], DiagnoseJob]) -> None:
        self._work, self._job = work, job
        self.on_take: Callable[[], None] | None = None

    def __call__(self, window: Window) -> dict[str, Any]:
        if self.on_take is not None:
            self.on_take()
        return self._work(self._job(window))

    @property
    def cpu_s(self) -> float:
        return float(getattr(self._work, "cpu_s", 0.0))

    def close(self) -> None:
        close = getattr(self._work, "close", None)
        if callable(close):
            close()


class DiagnosisNode(Node):
    """Inputs in; every period a diagnosis of the latest span out (see module doc)."""

    def __init__(self, *, context: Context | None = None, namespace: str = DEFAULT_NAMESPACE,
                 node_name: str = "pmsm_diagnose",
                 parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        p = declare_all(self, DEFAULTS, DIAGNOSE_SPECS)
        self.params = p
        self.plant, self.reference = reference(p, self.get_namespace())
        rate = float(p["sample_rate_hz"]) or (self.plant.sample_rate_hz if self.plant
                                              else PROVISIONAL_HZ)
        self.sizer = SpanSizer(p["span_s"], p["period_s"], rate, self._resize)
        span, period = self.sizer.sizes
        self.last: dict[str, Any] | None = None
        self.errors: deque[str] = deque(maxlen=20)
        self.last_failed: str | None = None
        self.published = 0
        self.skips_before_last = 0  # spans skipped before the previous diagnosis published
        self._skips_at_last = 0
        self.sim: LatestSpan | None = None
        fs_ns = round(1e9 / float(p["sample_rate_hz"])) if p["sample_rate_hz"] else None
        tol_ns = round(float(p["tolerance_s"]) * 1e9) or None
        self._spans = SpanDiagnosis(worker(self.plant, self.reference, str(p["worker"])),
                                    self._job)
        self.engine: OnlineEngine[dict[str, Any]] = OnlineEngine(
            EngineConfig(window=span, hop=period, queue_size=int(p["queue_size"]),
                         sample_rate_hz=float(p["sample_rate_hz"]),
                         tolerance_s=float(p["tolerance_s"]),
                         speed_source=str(p["speed_source"])),
            self._spans, speed_expected=lambda: self._speed_published(self.intake))
        try:
            self.intake = InputIntake(self, self._push)
            if self.plant is None:
                self.sim = LatestSpan(span, period, str(p["speed_source"]),
                                      lambda: self._speed_published(self.sim_intake),
                                      tol_ns, fs_ns)
                self.sim_sizer = SpanSizer(p["span_s"], p["period_s"], rate, self.sim.resize)
                self.sim_intake = InputIntake(self, self._push_sim, self.reference)
        except BaseException:
            self.engine.stop()  # ends the worker process
            raise
        self._pub = self.create_publisher(String, DIAGNOSIS, 10)
        self.numbers = NumberPublisher(self)
        self.numbers.prepare_diagnosis()
        self.health = HealthPublisher(self, "diagnose", diagnose_health(self))
        self._timer = self.create_timer(float(p["publish_period_s"]), self.publish_results)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.engine.start()

    # ------------------------------------------------------------------ inputs
    def _push(self, signal: str, stamp_ns: int, value: float) -> None:
        self.engine.push(signal, stamp_ns, value)
        self.sizer.check(self.engine.aligner.period_ns)

    def _push_sim(self, signal: str, stamp_ns: int, value: float) -> None:
        assert self.sim is not None
        self.sim.push(signal, stamp_ns, value)
        self.sim_sizer.check(self.sim.aligner.period_ns)

    def wake_on_window(self) -> GuardCondition:
        """From now on, each span the diagnosis thread takes wakes the executor spinning
        this node (the guard condition returned; see :meth:`.IdentifierNode.wake_on_window`)."""
        guard = self.create_guard_condition(lambda: None)
        self._spans.on_take = guard.trigger
        return guard

    def take_pending(self) -> None:
        """Take the input messages already delivered, without waiting for the executor."""
        self.intake.take_pending()
        if self.sim is not None:  # the reference is a simulator's topics
            self.sim_intake.take_pending()

    def _speed_published(self, intake: InputIntake | None) -> bool:
        return intake is not None and self.count_publishers(intake.topics["speed"]) > 0

    def _resize(self, span: int, period: int) -> None:
        self.engine.config = replace(self.engine.config, window=span, hop=period)
        self.engine.scheduler.resize(span, period, 0)

    def sample_rate_hz(self) -> float | None:
        """The drive's sample rate read from its stamps (None while unknown)."""
        period = self.engine.aligner.period_ns
        return 1e9 / period if period else None

    def _job(self, window: Window) -> DiagnoseJob:
        """The diagnosis of ``window`` with the options in effect now (worker thread)."""
        p, sim = self.params, self.sim
        options = {k: p[k] for k in OPTIONS}
        fs = self.sample_rate_hz() or PROVISIONAL_HZ
        if sim is None:
            return DiagnoseJob(window, fs, **options)
        return DiagnoseJob(window, fs, sim.latest, sim.sample_rate_hz or fs, **options)

    # ------------------------------------------------------------------ live parameters
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        return apply_or_refuse(self._apply, params)

    def _apply(self, changes: dict[str, Any]) -> None:
        candidate = {**self.params, **{k: v for k, v in changes.items() if k in self.params}}
        if {"span_s", "period_s"} & changes.keys():
            self.sizer.set_seconds(candidate["span_s"], candidate["period_s"])
            if self.sim is not None:
                self.sim_sizer.set_seconds(candidate["span_s"], candidate["period_s"])
        self.params = candidate
        self.get_logger().info(  # type: ignore[no-untyped-call]
            f"parameters changed: {', '.join(f'{k}={changes[k]}' for k in sorted(changes))} "
            "(from the next span on)")

    # ------------------------------------------------------------------ results
    def publish_results(self) -> None:
        """Publish what the worker finished (timer callback; also call at shutdown)."""
        for r in self.engine.drain():
            if isinstance(r, WindowError):
                self._failed(r)
            else:
                self._publish(r)

    def _failed(self, r: WindowError) -> None:
        text = f"span ending at {stamp_text(r.end_stamp, prefix='t=')}: {r.error}"
        self.errors.append(text)
        self.last_failed = text
        self.get_logger().warning(f"not diagnosed: {text}")  # type: ignore[no-untyped-call]

    def counts(self) -> dict[str, int]:
        """Spans due, diagnosed, skipped (latest wins) and failed so far."""
        st = self.engine.stats
        return {"diagnoses_due": st.windows_due, "diagnoses_run": st.windows_fitted,
                "diagnoses_skipped": st.windows_skipped, "diagnoses_failed": st.windows_failed}

    def _publish(self, d: dict[str, Any]) -> None:
        d["counts"] = self.counts()
        self._pub.publish(String(data=json.dumps(json_safe(d), allow_nan=False)))
        self.numbers.diagnosis(d)
        self.last, self.last_failed = d, None
        self.published += 1
        self.skips_before_last, self._skips_at_last = (self._skips_at_last,
                                                       d["counts"]["diagnoses_skipped"])
        log = self.get_logger()  # type: ignore[no-untyped-call]
        if diagnosed.mismatch(d):  # one call site per severity (rclpy's logger requires it)
            log.warning(diagnosed.line(d))
        else:
            log.info(diagnosed.line(d))

    # ------------------------------------------------------------------ summary
    def summary(self) -> dict[str, Any]:
        """Counters and the latest diagnosis (the ``run --json`` summary's diagnose part)."""
        st = self.engine.stats
        ref = {"plant_file": self.reference} if self.plant is not None else {
            "sim_namespace": self.reference}
        return {**self.counts(), **ref, "period_s": self.params["period_s"],
                "span_s": self.params["span_s"], "sample_rate_hz": self.sample_rate_hz(),
                "samples_received": st.samples_received,
                "diagnosis_latency_p50_ms": st.fit_latency_p50_ms,
                "diagnosis_latency_p99_ms": st.fit_latency_p99_ms,
                "diagnosis_cpu_s": st.fit_cpu_s, "errors": list(self.errors),
                "sim_samples_received": (self.sim.aligner.samples_emitted
                                         if self.sim is not None else None),
                "last_diagnosis": self.last}

    def destroy_node(self) -> None:
        self.engine.stop()
        super().destroy_node()  # type: ignore[no-untyped-call]
