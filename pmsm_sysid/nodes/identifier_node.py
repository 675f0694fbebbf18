"""IdentifierNode: online NARX identification on the live topics.

The node lives in the pipeline's namespace ``<ns>`` (default ``/pmsm``: node
``/pmsm/pmsm_identifier``) and every topic name below is relative to it. Subscribes to
``<ns>/thrust|speed|position`` or, with ``input_layout: joint_state``, to one
``sensor_msgs/JointState`` topic (``joint_state_topic``, default ``/joint_states``, where
ros2_control's joint_state_broadcaster publishes; ``effort``/``velocity``/``position`` of
``joint_name``; a namespaced robot: set the topic or remap ``/joint_states``). The work is done by
:class:`pmsm_sysid.core.online.engine.OnlineEngine` (alignment,
window ring, fitting thread) around :class:`pmsm_sysid.core.online.tracker.WindowTracker` (fits,
cross-validation, change detection), which runs in a worker process of its own (parameter
``fit_worker: process``, the default; ``thread`` runs it in the engine's fitting thread);
``__init__`` only wires parameters, subscriptions (keep-last 10000: a starved process
catches up without a loss; each callback also takes what already waits),
publishers and one timer that publishes finished results:

* ``<ns>/model`` (std_msgs/String): one identify-JSON per output and window, plus
  ``window`` {start_stamp, end_stamp, seq, ...}, ``fit_time_ms`` and ``model_id``;
* ``<ns>/validation`` (diagnostic_msgs/DiagnosticArray): status
  ``identifier/cross_validation/<output>`` per validated model (OK = pass, WARN = fail);
* ``<ns>/change`` (DiagnosticArray): status ``identifier/change/<output>`` at level
  WARN for each detected plant change.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.context import Context
from rclpy.guard_condition import GuardCondition
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ..bagio.cdr import decode_stamped
from ..clocktext import stamp_text
from ..core.errors import DataError
from ..core.frequency.analysis import json_safe
from ..core.online.engine import EngineConfig, OnlineEngine, WindowError
from ..core.online.inputs import InputReport, describe_inputs
from ..core.online.tracker import TrackerConfig, WindowResult, WindowTracker, tracker_config
from ..core.online.windows import Window
from ..core.online.workerproc import ProcessWorker
from ..rosutil import SLACK_DEPTH, data_qos, message_class, sample_value, stamp_from_ns, stamp_to_ns
from ..topics import (
    CHANGE,
    DEFAULT_NAMESPACE,
    INPUT_TYPES,
    JOINT_STATE_TYPE,
    MODEL,
    MODEL_DEPTH,
    VALIDATION,
)
from .defaults import IDENTIFIER_DEFAULTS
from .health import HealthPublisher, IdentifierHealth
from .identifier_status import OK, WARN, change_status, status, validation_statuses
from .numbers import NumberPublisher
from .params import (
    IDENTIFIER_SPECS,
    TRACKER_KEYS,
    SwitchableProcessor,
    apply_or_refuse,
    check_identifier,
    declare_all,
)

DRAIN_ROUNDS = 100  # at most 300 input messages taken per subscription callback

#: Parameters and their defaults (:mod:`.defaults`, importable without ROS).
DEFAULTS: dict[str, Any] = IDENTIFIER_DEFAULTS
FIT_WORKERS = ("process", "thread")


def fit_processor(config: TrackerConfig, where: str) -> Callable[[Window], WindowResult]:
    """``WindowTracker(config).process``, in a worker process of its own (``process``: the
    fits neither hold this process's GIL nor wait for it) or called in the engine's fitting
    thread (``thread``)."""
    if where == "thread":
        return WindowTracker(config).process
    return ProcessWorker[Window, WindowResult](WindowTracker, (config,), method="process")


def _shape(w: Window) -> tuple[int, int]:
    """(samples, history) of a window: which settings it was cut with."""
    return (w.stop_index - w.start_index, w.history)


class IdentifierNode(Node):
    """Online identification: aligned samples -> windows -> models, validation, changes."""

    def __init__(self, *, context: Context | None = None, namespace: str = DEFAULT_NAMESPACE,
                 node_name: str = "pmsm_identifier",
                 parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        p = declare_all(self, DEFAULTS, IDENTIFIER_SPECS)
        check_identifier(p)
        self.params = p
        config = tracker_config(p)
        if p["fit_worker"] not in FIT_WORKERS:
            raise DataError(f"fit_worker must be 'process' or 'thread', got '{p['fit_worker']}'")
        self._fit = SwitchableProcessor(fit_processor(config, p["fit_worker"]), _shape)
        self.engine: OnlineEngine[WindowResult] = OnlineEngine(
            EngineConfig(window=int(p["window"]), hop=int(p["hop"]),
                         history=config.history, queue_size=int(p["queue_size"]),
                         sample_rate_hz=float(p["sample_rate_hz"]),
                         tolerance_s=float(p["tolerance_s"]),
                         speed_source=str(p["speed_source"])),
            self._fit, speed_expected=self._speed_published)
        self.settings_changes = 0
        self.last: dict[str, Any] = {"models": {}, "validation": {}, "changes": []}
        #: per output: [cross-validations passed, cross-validations made] over the run
        self.validation_counts: dict[str, list[int]] = {}
        self.models_published = 0
        self.errors: list[str] = []
        self._last_input: float | None = None  # time.monotonic() of the newest input message
        self.stale = False
        self._input_ended = False  # this pipeline's sim has published its last sample
        self.input_held = False  # this pipeline holds its sim on purpose (a worker is busy)
        self.stale_events = 0
        self._model_pub = self.create_publisher(String, MODEL, MODEL_DEPTH)
        self._val_pub = self.create_publisher(DiagnosticArray, VALIDATION, 50)
        self._change_pub = self.create_publisher(DiagnosticArray, CHANGE, 50)
        self.numbers = NumberPublisher(self)
        self.health_report = IdentifierHealth(self)
        self.health = HealthPublisher(self, "identifier", self.health_report)
        try:
            self._input_topics = self._layout(p)
            self._started = time.monotonic()
            self._inputs_logged: tuple[Any, ...] | None = None
            self.input_log: list[str] = []  # the lines logged about the inputs (latest 20)
            self._subscribe(p)
        except BaseException:
            self.engine.stop()  # ends the worker process
            raise
        self._timer = self.create_timer(float(p["publish_period_s"]), self.publish_results)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.engine.start()

    # ------------------------------------------------------------------ live parameters
    def _processor(self, config: TrackerConfig) -> Callable[[Window], WindowResult]:
        return fit_processor(config, str(self.params["fit_worker"]))

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Validate a change as a whole; apply it to the next windows (see :mod:`.params`)."""
        return apply_or_refuse(self._apply, params)

    def _apply(self, changes: dict[str, Any]) -> None:
        candidate = {**self.params, **{k: v for k, v in changes.items() if k in self.params}}
        for k, v in candidate.items():
            if isinstance(v, (list, tuple)) or type(v).__name__ == "array":
                candidate[k] = list(v)
        check_identifier(candidate)
        if TRACKER_KEYS & changes.keys():
            config = tracker_config(candidate)
            process = self._processor(config)  # first: nothing changes if this fails
            self.engine.config = replace(self.engine.config, window=config.window,
                                         hop=config.hop, history=config.history)
            self.engine.scheduler.resize(config.window, config.hop, config.history)
            self._fit.switch(process, (config.window, config.history))
            self.settings_changes += 1
        self.params = candidate
        self.get_logger().info(  # type: ignore[no-untyped-call]
            f"parameters changed: {', '.join(f'{k}={changes[k]}' for k in sorted(changes))} "
            "(fits: from the next window on)")

    def _subscribe(self, p: dict[str, Any]) -> None:
        if p["input_layout"] == "topics":
            self._types = {sig: message_class(t) for sig, t in INPUT_TYPES.items()}
            self._subs = {sig: self.create_subscription(
                self._types[sig], sig, self._on_raw(sig), data_qos(SLACK_DEPTH),
                raw=True) for sig in INPUT_TYPES}
        elif p["input_layout"] == "joint_state":
            if not p["joint_name"]:
                raise DataError("input_layout joint_state needs the joint_name parameter")
            self._joint_sub = self.create_subscription(
                JointState, p["joint_state_topic"], self._on_joint_state, data_qos(SLACK_DEPTH))
        else:
            raise DataError(f"input_layout must be 'topics' or 'joint_state', got "
                            f"'{p['input_layout']}'")

    def _layout(self, p: dict[str, Any]) -> dict[str, str]:
        """signal -> the full name of the topic it comes from."""
        if p["input_layout"] == "joint_state":
            return dict.fromkeys(INPUT_TYPES,
                                 self.resolve_topic_name(str(p["joint_state_topic"])))
        return {sig: self.resolve_topic_name(sig) for sig in INPUT_TYPES}

    @property
    def input_topic_types(self) -> dict[str, str]:
        """topic -> message type of the topics the samples come from (remaps applied)."""
        if self.params["input_layout"] == "joint_state":
            return dict.fromkeys(self._input_topics.values(), JOINT_STATE_TYPE)
        return {self._input_topics[sig]: t for sig, t in INPUT_TYPES.items()}

    def _speed_published(self) -> bool:
        """Someone publishes the speed topic (then its messages are worth waiting for)."""
        if self.params["input_layout"] != "topics":
            return False
        return self.count_publishers(self._input_topics["speed"]) > 0

    def _on_raw(self, sig: str) -> Any:
        def callback(data: bytes) -> None:
            self._take(sig, data)
            self._drain()

        return callback

    def _take(self, sig: str, data: bytes) -> None:
        """One serialized input message: stamp and value straight from its CDR bytes."""
        self._input_seen()
        got = decode_stamped(data)
        if got is None:  # not little-endian CDR: the generic deserializer
            got = self._decode(sig, data)
        self.engine.push(sig, *got)

    def _decode(self, sig: str, data: bytes) -> tuple[int, float]:
        msg = deserialize_message(data, self._types[sig])
        return stamp_to_ns(msg.header.stamp), sample_value(sig, msg)

    def _drain(self) -> None:
        """Take what already waits on the three input subscriptions, round robin, up to
        ``DRAIN_ROUNDS`` rounds: a burst costs one executor callback, not one per message
        (the executor's own work per callback is what limits the intake rate)."""
        subs = [(sig, sub.handle, sub.msg_type) for sig, sub in self._subs.items()]
        push, took_any = self.engine.push, False
        with subs[0][1], subs[1][1], subs[2][1]:
            for _ in range(DRAIN_ROUNDS):
                took = False
                for sig, handle, msg_type in subs:
                    got = handle.take_message(msg_type, True)
                    if got is not None:
                        took = True
                        value = decode_stamped(got[0])
                        if value is None:  # not little-endian CDR: the generic deserializer
                            value = self._decode(sig, got[0])
                        push(sig, *value)
                if not took:
                    break
                took_any = True
        if took_any:
            self._input_seen()

    def wake_on_window(self) -> GuardCondition:
        """From now on, each window the fitting thread takes wakes the executor spinning
        this node (the guard condition returned): a pipeline that holds its sim while a
        window waits for the fitting worker sleeps until then instead of polling."""
        guard = self.create_guard_condition(lambda: None)
        self._fit.on_take = guard.trigger
        return guard

    def take_pending(self) -> None:
        """Take the input messages already delivered, without waiting for the executor
        (a pipeline that steps the sim itself calls it after each burst: the executor's
        own work per round costs more than the messages)."""
        if self.params["input_layout"] == "joint_state":
            self._drain_joint()
        else:
            self._drain()

    def _on_joint_state(self, msg: Any) -> None:
        """One JointState message, then what already waits (as :meth:`_drain`)."""
        self._take_joint(msg)
        self._drain_joint()

    def _drain_joint(self) -> None:
        sub = self._joint_sub
        for _ in range(3 * DRAIN_ROUNDS):
            with sub.handle:
                got = sub.handle.take_message(sub.msg_type, False)
            if got is None:
                return
            self._take_joint(got[0])

    def _take_joint(self, msg: Any) -> None:
        self._input_seen()
        try:
            i = list(msg.name).index(self.params["joint_name"])
            # a position-only joint publishes no velocity: speed is then derived
            speed = msg.velocity[i] if len(msg.velocity) > i else float("nan")
            values = (msg.effort[i], speed, msg.position[i])
        except (ValueError, IndexError):
            self.engine.aligner.count_unaligned(3)  # no such joint, or a short array
            return
        self.engine.push_sample(stamp_to_ns(msg.header.stamp), values)

    # ------------------------------------------------------------------ publishing
    def _input_seen(self) -> None:
        self._last_input = time.monotonic()
        if self.stale:
            self._report_stale(False, 0.0)

    def input_age_s(self) -> float | None:
        """Seconds since the newest input message (None before the first one)."""
        return None if self._last_input is None else time.monotonic() - self._last_input

    def restart_input_clock(self) -> None:
        """The inputs start now (the pipeline held its sim until a recorder was ready): the
        account of the inputs is due ``inputs_report_s`` from here."""
        self._started = time.monotonic()

    def end_of_input(self) -> None:
        """The sim of this pipeline published its last sample: silence from now on is the
        end of the run, not stale input."""
        self._input_ended = True

    def hold_input(self, held: bool) -> None:
        """This pipeline holds its sim while a worker catches up (``True``) or lets it run
        again: silence while held is not stale input, and the age restarts on release."""
        if self.input_held and not held and self._last_input is not None:
            self._last_input = time.monotonic()
        self.input_held = held

    def _check_stale(self) -> None:
        age = self.input_age_s()
        if self._input_ended or self.input_held:
            return
        if age is not None and not self.stale and age > float(self.params["stale_after_s"]):
            self._report_stale(True, age)

    def _report_stale(self, stale: bool, age: float) -> None:
        """Input went silent (WARN, once) or came back (OK) on the validation topic."""
        self.stale = stale
        self.stale_events += int(stale)
        text = f"stale input: no sample for {age:.1f} s" if stale else "input resumed"
        if stale:
            self.get_logger().warning(text)  # type: ignore[no-untyped-call]
        arr = DiagnosticArray(status=[status("identifier/input", WARN if stale else OK, text,
                                             self.get_name(), {"input_age_s": age})])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._val_pub.publish(arr)

    def input_report(self) -> InputReport:
        """Which input topics were expected, which arrived (with rates), which never came."""
        a = self.engine.aligner
        return describe_inputs(self._input_topics, a.counts, a.mode, a.samples_emitted)

    def _check_inputs(self) -> None:
        """Log the account of the inputs once ``inputs_report_s`` have passed, and again
        whenever what arrived (or what is wrong) changes."""
        if time.monotonic() - self._started < float(self.params["inputs_report_s"]):
            return
        rep = self.input_report()
        key = (tuple(rep.arrived), rep.speed, rep.problem, rep.samples > 0)
        if key != self._inputs_logged:
            self._inputs_logged = key
            self.input_log.append(rep.line())
            del self.input_log[:-20]
            log = self.get_logger()  # type: ignore[no-untyped-call]
            if rep.problem:
                log.warning(rep.line())
            else:
                log.info(rep.line())

    def publish_results(self) -> None:
        """Publish what the fitting thread finished (timer callback; also call at shutdown)."""
        self._check_stale()
        self._check_inputs()
        for r in self.engine.drain():
            if isinstance(r, WindowError):
                self._note_error(f"window {r.seq}: {r.error}")
            else:
                self._publish(r)

    def _note_error(self, text: str) -> None:
        self.errors.append(text)
        del self.errors[:-20]
        self.get_logger().warning(f"not fitted: {text}")  # type: ignore[no-untyped-call]

    def _publish(self, r: WindowResult) -> None:
        for e in r.errors:
            self._note_error(f"{e['model_id']}: {e['error']}")
        for model in r.models:
            # a diverged free run has NMSE inf: strict JSON carries it as null (as identify)
            self._model_pub.publish(String(data=json.dumps(json_safe(model), allow_nan=False)))
            self.last["models"][model["output"]] = model
            self.models_published += 1
            self.numbers.model(model)
        self.health_report.note(r)
        for d in r.decisions:
            self.numbers.decision(d)
        stamp = stamp_from_ns(round(r.end_stamp * 1e9))
        if r.validations:
            for v in r.validations:
                self.last["validation"][v["output"]] = v
                self.numbers.validation(v)
                count = self.validation_counts.setdefault(v["output"], [0, 0])
                count[0] += bool(v["pass"])
                count[1] += 1
            arr = DiagnosticArray(status=validation_statuses(
                r.validations, r.decisions, float(self.params["change.s_confirm"]),
                self.validation_counts, self.window_grid()))
            arr.header.stamp = stamp
            self._val_pub.publish(arr)
        if r.changes:
            arr = DiagnosticArray(status=[change_status(c) for c in r.changes])
            arr.header.stamp = stamp
            self._change_pub.publish(arr)
            self.last["changes"].extend(r.changes)
            del self.last["changes"][:-100]
            for c in r.changes:
                self.get_logger().warning(  # type: ignore[no-untyped-call]
                    f"plant change on {c['output']} at {stamp_text(c['window']['end_stamp'], 3)}: "
                    f"{c['reasons']}")

    # ------------------------------------------------------------------ summary
    def window_grid(self) -> dict[str, int]:
        """The windows' length and hop in samples (the run verdict's overlap)."""
        return {"window": int(self.params["window"]), "hop": int(self.params["hop"])}

    def summary(self) -> dict[str, Any]:
        """Counters and the latest results (the ``run --json`` summary's identifier part)."""
        return {**self.engine.stats.to_dict(), "inputs": self.input_report().to_dict(),
                "speed_derived": self.engine.aligner.speed_derived,
                "input_log": list(self.input_log), "input_stale": self.stale,
                "stale_events": self.stale_events, "last_input_age_s": self.input_age_s(),
                "models": dict(self.last["models"]),
                "validation": dict(self.last["validation"]),
                "validation_counts": {k: list(v) for k, v in self.validation_counts.items()},
                "window_grid": self.window_grid(),
                "change_events": list(self.last["changes"]), "errors": list(self.errors)}

    def destroy_node(self) -> None:
        self.engine.stop()
        super().destroy_node()  # type: ignore[no-untyped-call]
