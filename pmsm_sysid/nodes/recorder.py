"""RecorderNode: subscribes with ``raw=True`` and stores the CDR bytes through a BagRecorder.

- Topics: by default the inputs, the identification and diagnosis outputs and the plottable
  numbers of the models under the namespace (``<ns>/thrust``, ``<ns>/model``,
  ``<ns>/diagnosis``, ``<ns>/stats/speed/free_run_r2``, ...; the diagnosis's numbers are in
  its JSON, so its own ``stats`` topics are not recorded by default; the node itself is
  ``<ns>/pmsm_record``); ``inputs`` (topic -> type) replaces the three input
  topics, e.g. by the ``JointState`` topic an identifier listens to; with ``topics`` exactly
  those (relative names are resolved in the namespace). Topics of known type are subscribed at
  once (nothing published after the recorder starts is missed); others when they show up in
  the ROS graph, with the type and reliability their publishers offer.
- QoS: reliable, keep-last ``depth`` (default 10000 per topic, 20 s at 500 Hz) so bursts from a
  fast replay or a busy executor are absorbed rather than overwritten.
- Bag timestamp = the middleware's receive time of the message (``received_timestamp``).
  A topic enters the bag with its first message, so the bag lists only topics that carried
  data. The bag is flushed (readable, crash-safe) every ``flush_period_s`` (0.5 s).
- Intake: each subscription callback also takes what already waits on every recorded topic
  (up to ``DRAIN_ROUNDS`` rounds), so a burst costs one executor round, not one per message.
- Losses are not silent: on the input topics the header stamps are followed, and a stamp
  step of more than 1.5 sample periods counts the samples it skips (``summary()``).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from ..bagio import BagRecorder
from ..bagio.cdr import decode_stamped
from ..rosutil import data_qos, message_class
from ..topics import (
    DEFAULT_NAMESPACE,
    INPUT_TYPES,
    OUTPUT_TYPES,
    STAT_TOPICS,
    normalize_namespace,
    stat_topic,
    topic_name,
)
from .health import HealthPublisher, recorder_health

STAT_OUTPUTS = ("speed", "position")  # outputs whose plottable numbers are recorded by default
DRAIN_ROUNDS = 100


def default_topics(namespace: str, inputs: Mapping[str, str] | None = None) -> dict[str, str]:
    """topic -> type recorded by default: the three inputs (or ``inputs``, topic -> type),
    the identification outputs and the plottable numbers of the speed and position models,
    all under ``namespace``."""
    rel = {**({} if inputs is not None else INPUT_TYPES), **OUTPUT_TYPES,
           **{stat_topic(o, q): t for o in STAT_OUTPUTS for q, (t, _, _) in STAT_TOPICS.items()}}
    return {**{topic_name(namespace, name): t for name, t in rel.items()}, **(inputs or {})}


def known_type(topic: str, namespace: str = DEFAULT_NAMESPACE) -> str | None:
    """The type of the full topic name ``topic`` when its name fixes it (an input under any
    namespace, or an output or plottable number under ``namespace``), else None."""
    ns = normalize_namespace(namespace).rstrip("/") + "/"
    rel = topic[len(ns):] if topic.startswith(ns) else None
    if rel is not None:
        for name, t in default_topics("/").items():
            if name == "/" + rel:
                return t
    return INPUT_TYPES.get(topic.rsplit("/", 1)[-1])


class RecorderNode(Node):
    """Writes every message on the chosen topics into ``recorder`` (see module docstring)."""

    def __init__(self, recorder: BagRecorder, *, context: Context | None = None,
                 namespace: str = DEFAULT_NAMESPACE, topics: Sequence[str] | None = None,
                 depth: int = 10000, flush_period_s: float = 0.5,
                 node_name: str = "pmsm_record", inputs: Mapping[str, str] | None = None,
                 ) -> None:
        super().__init__(node_name, context=context, namespace=namespace)
        self.recorder = recorder
        self.depth = depth
        self.counts: Counter[str] = Counter()
        inputs = None if inputs is None else {self.resolve_topic_name(t): ty
                                              for t, ty in inputs.items()}
        self.inputs = ({topic_name(self.get_namespace(), s) for s in INPUT_TYPES}
                       if inputs is None else set(inputs))
        self._last_stamp: dict[str, int] = {}
        self._period: dict[str, int] = {}
        self.gaps: Counter[str] = Counter()
        self.missing: Counter[str] = Counter()
        self._subs: list[tuple[str, str, Any]] = []
        self.first_receive_ns: int | None = None
        ns = self.get_namespace()
        wanted = {self.resolve_topic_name(t): ty
                  for t, ty in default_topics(ns, inputs).items()} \
            if topics is None else {self.resolve_topic_name(t):
                                    known_type(self.resolve_topic_name(t), ns) for t in topics}
        self.pending = {t for t, ty in wanted.items() if ty is None}
        self.types: dict[str, str] = {}
        for topic, msgtype in wanted.items():
            if msgtype is not None:
                self._subscribe(topic, msgtype, reliable=True)
        self.create_timer(flush_period_s, recorder.flush)
        self.health = HealthPublisher(self, "record", recorder_health(self))
        if self.pending:
            self.create_timer(0.25, self._discover)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def _subscribe(self, topic: str, msgtype: str, reliable: bool) -> None:
        qos = data_qos(self.depth)
        if not reliable:
            qos = QoSProfile(depth=self.depth,  # type: ignore[no-untyped-call]
                             reliability=ReliabilityPolicy.BEST_EFFORT)
        self.types[topic] = msgtype
        callback: Any = self._writer(topic, msgtype)  # rclpy passes MessageInfo to 2-arg ones
        sub = self.create_subscription(message_class(msgtype), topic, callback, qos, raw=True)
        self._subs.append((topic, msgtype, sub))

    def _writer(self, topic: str, msgtype: str) -> Callable[[bytes, Any], None]:
        def callback(data: bytes, info: Any) -> None:
            self._store(topic, msgtype, data, info)
            self._drain()

        return callback

    def _store(self, topic: str, msgtype: str, data: bytes, info: Any) -> None:
        stamp = int(info.get("received_timestamp") or 0) or time.time_ns()
        if not self.counts[topic]:
            self.recorder.add_topic(topic, msgtype)
            if self.first_receive_ns is None:
                self.first_receive_ns = stamp
        self.recorder.write(topic, stamp, data)
        self.counts[topic] += 1
        if topic in self.inputs:
            self._follow(topic, data)

    def _follow(self, topic: str, data: bytes) -> None:
        """Count stamp gaps (samples lost before they reached the bag) of an input topic."""
        got = decode_stamped(data)
        if got is None:
            return
        stamp, last = got[0], self._last_stamp.get(topic)
        self._last_stamp[topic] = stamp
        if last is None:
            return
        step = stamp - last
        if step <= 0:
            return
        period = min(self._period.get(topic, step), step)
        self._period[topic] = period
        if step > 1.5 * period:
            self.gaps[topic] += 1
            self.missing[topic] += round(step / period) - 1

    def _drain(self) -> None:
        """Take what already waits on the recorded topics, round robin (see module doc)."""
        for _ in range(DRAIN_ROUNDS):
            took = False
            for topic, msgtype, sub in self._subs:
                took = self._take_one(topic, msgtype, sub) is not None or took
            if not took:
                return

    def take_received_before(self, stop_ns: int) -> int:
        """Store every message that reached this process before ``stop_ns`` (system clock).

        Takes each topic's waiting messages in order until its queue is empty or it yields a
        message received after ``stop_ns`` (stored too: it is real data). The work is bounded
        by what is queued, not by time, so a starved recorder still keeps every message that
        arrived before it was told to stop. Returns how many messages it stored.
        """
        stored = 0
        for topic, msgtype, sub in self._subs:
            while (info := self._take_one(topic, msgtype, sub)) is not None:
                stored += 1
                if int(info.get("received_timestamp") or 0) > stop_ns:
                    break
        return stored

    def _take_one(self, topic: str, msgtype: str, sub: Any) -> Any:
        """Store the next message waiting on ``sub``; its message info, or None if none."""
        with sub.handle:
            got = sub.handle.take_message(sub.msg_type, True)
        if got is None:
            return None
        self._store(topic, msgtype, got[0], got[1])
        return got[1]

    def summary(self) -> dict[str, Any]:
        """Messages per topic, and the stamp gaps and samples missing per input topic."""
        return {"messages": self.total, "topics": dict(self.counts),
                "stamp_gaps": dict(self.gaps), "samples_missing": dict(self.missing),
                "path": str(self.recorder.path)}

    def _discover(self) -> None:
        """Subscribe to pending topics once a publisher shows their type."""
        found = dict(self.get_topic_names_and_types())
        for topic in sorted(self.pending):
            msgtypes = found.get(topic, [])
            if not msgtypes:
                continue
            infos = self.get_publishers_info_by_topic(topic)
            reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
            self._subscribe(topic, msgtypes[0], reliable)
            self.pending.discard(topic)
            self.get_logger().info(  # type: ignore[no-untyped-call]
                f"recording {topic} ({msgtypes[0]})")
