"""ReplayerNode: publishes a recording's serialized messages on their recorded topics and types.

The CDR bytes go out unchanged (rclpy publishers accept ``bytes``), so a replayed message is
bit-for-bit the recorded one. Phases, driven by a timer that ticks every 1 ms while playing
and every 10 ms otherwise (a replay waiting for its subscribers wakes the executor, and every
node it spins, a tenth as often):

1. **wait** until every topic to wait for has ``subscribers`` matched subscriptions (the
   publisher's DDS ``matched`` event, not the graph cache, which can run ahead of the DDS
   match and lose the first messages), or ``wait_s`` has passed; then **settle**
   ``settle_s`` more so that the subscribers' side of the discovery completes too;
2. **play**: paced by the bag timestamps x 1/``rate``; with ``rate = 0`` as fast as the
   subscribers' queues allow: bursts of at most ``burst`` messages per topic, each followed by
   a pause long enough for a subscriber that drains ``drain_rate`` messages per second. A
   burst below the data QoS depth (1000) cannot overflow a keep-last queue of a subscriber
   that keeps that pace; plain flat-out publishing overflowed them on this machine;
3. ``loop``: pass p republishes every message with header stamps and bag times shifted by
   p x (span + one period), span being the largest of the bag-time span and the header-stamp
   span and the period the median stamp step of the first topic, so stamps keep strictly
   increasing across passes; the header stamp is patched in the CDR bytes (messages whose
   first field is ``std_msgs/Header``), nothing else changes;
4. **linger** ``linger_s`` with the publishers alive so the tail is delivered, then finished.
"""

from __future__ import annotations

import struct
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rclpy.context import Context
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node

from ..bagio import RawMessage, bag_topics, iter_raw
from ..core.errors import BagError
from ..rosutil import SLACK_DEPTH, data_qos, message_class
from ..topics import INPUT_TYPES
from .health import HealthPublisher, replay_health

#: The phases' timer periods (s): pacing the playback, and waiting, settling or lingering.
PLAY_TICK_S = 0.001
IDLE_TICK_S = 0.01

# --- planning (no ROS) --------------------------------------------------------------------

def publishable(topics: dict[str, str]) -> tuple[dict[str, str], dict[str, str]]:
    """Split topic -> type into (types rclpy can publish here, the others)."""
    ok, skipped = {}, {}
    for topic, msgtype in topics.items():
        try:
            message_class(msgtype)
        except BagError:
            skipped[topic] = msgtype
        else:
            ok[topic] = msgtype
    return ok, skipped


def is_input(topic: str, msgtype: str) -> bool:
    """True for ``<ns>/thrust|speed|position`` carrying the standard type."""
    return INPUT_TYPES.get(topic.rsplit("/", 1)[-1]) == msgtype


def input_prefix(topics: dict[str, str]) -> str | None:
    """The namespace of the standard input topics in a bag (``/pmsm``), None if absent."""
    prefixes = {t.rsplit("/", 1)[0] for t, ty in topics.items() if is_input(t, ty)}
    if len(prefixes) > 1:
        raise BagError(f"several input namespaces in the bag ({', '.join(sorted(prefixes))})")
    return prefixes.pop() if prefixes else None


def remap_topics(topics: dict[str, str], namespace: str | None) -> dict[str, str]:
    """recorded topic -> published topic: the input namespace, and every topic under it
    (the pipeline's outputs and plottable numbers), moved to ``namespace``."""
    if namespace is None:
        return {t: t for t in topics}
    old = input_prefix(topics)
    if old is None:
        raise BagError("--namespace given but the bag has no <ns>/thrust|speed|position topics")
    new = "/" + namespace.strip("/") if namespace.strip("/") else ""
    return {t: (new + t[len(old):] if t.startswith(old + "/") else t) for t in topics}


def header_stamp_ns(data: bytes) -> int:
    """header.stamp of a CDR message whose first field is std_msgs/Header."""
    sec, nanosec = struct.unpack_from("<iI" if data[1] & 1 else ">iI", data, 4)
    return int(sec) * 1_000_000_000 + int(nanosec)


def with_header_stamp(data: bytes, ns: int) -> bytes:
    """``data`` with header.stamp replaced by ``ns``; every other byte unchanged."""
    sec, nanosec = divmod(ns, 1_000_000_000)
    head = struct.pack("<iI" if data[1] & 1 else ">iI", sec, nanosec)
    return data[:4] + head + data[12:]


def has_header(msgtype: str) -> bool:
    """True if the first field of ``msgtype`` is a std_msgs/Header."""
    fields = message_class(msgtype).get_fields_and_field_types()
    return next(iter(fields.items()), ("", ""))[1] == "std_msgs/Header"


def loop_offset_ns(path: str | Path, headers: dict[str, bool]) -> int:
    """Shift per loop pass: max(bag-time span, header-stamp span) + median stamp step."""
    times: list[int] = []
    first_topic: str | None = None
    steps: list[int] = []
    stamps: list[int] = []
    last: int | None = None
    for m in iter_raw(path, headers):
        times.append(m.timestamp_ns)
        first_topic = first_topic or m.topic
        if m.topic == first_topic:
            value = header_stamp_ns(m.data) if headers[m.topic] else m.timestamp_ns
            if last is not None:
                steps.append(value - last)
            last = value
        if headers[m.topic]:
            stamps.append(header_stamp_ns(m.data))
    if len(steps) < 1:
        raise BagError(f"{path}: --loop needs at least two messages on {first_topic}")
    steps.sort()
    period = max(steps[len(steps) // 2], 1)
    span = max(max(times) - min(times), (max(stamps) - min(stamps)) if stamps else 0)
    return span + period


# --- the node -----------------------------------------------------------------------------

@dataclass
class _Pass:
    index: int
    messages: Iterator[RawMessage]
    pending: RawMessage | None = None


@dataclass
class ReplayStats:
    """What was published (per published topic), to how many subscribers, in how many
    passes."""

    counts: Counter[str] = field(default_factory=Counter)
    listeners: Counter[str] = field(default_factory=Counter)  # most subscribers at once
    at_start: dict[str, int] = field(default_factory=dict)  # subscribers when playing began
    passes: int = 0
    waited_s: float = 0.0
    matched: bool = False


class ReplayerNode(Node):
    """Publishes one bag (see the module docstring); ``finished`` once done."""

    def __init__(self, path: str | Path, *, context: Context | None = None,
                 rate: float = 1.0, loops: int = 1, namespace: str | None = None,
                 wait_s: float = 10.0, settle_s: float = 0.25, linger_s: float = 1.0,
                 subscribers: int = 1,
                 burst: int = 500, drain_rate: float = 5000.0,
                 node_name: str = "pmsm_replay") -> None:
        topics, skipped = publishable(bag_topics(Path(path)))
        if not topics:
            raise BagError(f"{path}: no topic with a message type available here "
                           f"(skipped: {', '.join(sorted(skipped))})")
        remap = remap_topics(topics, namespace)
        home = namespace if namespace is not None else input_prefix(topics) or "/"
        super().__init__(node_name, context=context, namespace=home)
        self.path = Path(path)
        self.rate, self.loops, self.burst, self.drain_rate = rate, loops, burst, drain_rate
        self.wait_s, self.settle_s, self.linger_s = wait_s, settle_s, linger_s
        self.subscribers = max(1, subscribers)
        self.topics, self.skipped, self.remap = topics, skipped, remap
        self.headers = {t: has_header(ty) for t, ty in self.topics.items()}
        self.offset_ns = loop_offset_ns(self.path, self.headers) if loops != 1 else 0
        self.matched: dict[str, int] = {}
        self.stats = ReplayStats()
        self._pubs = {t: self._publisher(t, ty) for t, ty in self.topics.items()}
        inputs = [self.remap[t] for t, ty in self.topics.items() if is_input(t, ty)]
        self.wait_for = inputs or list(self.remap.values())
        self.finished = False
        self._phase, self._phase_t = "wait", time.monotonic()
        self._pass: _Pass | None = None
        self._t0: tuple[float, int] | None = None  # (monotonic, first bag time) of playback
        self._resume = 0.0
        self._timer = self.create_timer(IDLE_TICK_S, self._on_timer)
        self.health = HealthPublisher(self, "replay", replay_health(self))

    def _publisher(self, topic: str, msgtype: str) -> Any:
        out = self.remap[topic]

        def on_matched(info: Any) -> None:
            self.matched[out] = int(info.current_count)
            self.stats.listeners[out] = max(self.stats.listeners[out], int(info.current_count))

        return self.create_publisher(message_class(msgtype), out, data_qos(SLACK_DEPTH),
                                     event_callbacks=PublisherEventCallbacks(matched=on_matched))

    # ------------------------------------------------------------------ phases
    def _on_timer(self) -> None:
        now = time.monotonic()
        if self._phase == "wait":
            ready = all(self.matched.get(t, 0) >= self.subscribers for t in self.wait_for)
            if ready or now - self._phase_t >= self.wait_s:
                self.stats.matched, self.stats.waited_s = ready, now - self._phase_t
                self._phase, self._phase_t = "settle", now
        elif self._phase == "settle":
            if now - self._phase_t >= self.settle_s:
                self._phase = "play"
                self._tick(PLAY_TICK_S)
                self.stats.at_start = {t: self.matched.get(t, 0) for t in self.remap.values()}
                self._start_pass(0)
        elif self._phase == "play":
            if now >= self._resume:
                self._play(now)
        elif self._phase == "linger" and now - self._phase_t >= self.linger_s:
            self._phase, self.finished = "done", True
            self._timer.cancel()  # type: ignore[no-untyped-call]

    def _tick(self, period_s: float) -> None:
        self._timer.timer_period_ns = round(period_s * 1e9)

    def _start_pass(self, index: int) -> None:
        self._pass = _Pass(index, iter_raw(self.path, self.topics))
        self.stats.passes = index + 1

    def _next(self) -> RawMessage | None:
        """The next message of the playback, shifted for the current pass; None at the end."""
        p = self._pass
        assert p is not None
        if p.pending is None:
            p.pending = next(p.messages, None)
            if p.pending is None:
                if self.loops and p.index + 1 >= self.loops:
                    return None
                self._start_pass(p.index + 1)
                return self._next()
            if p.index:
                shift = p.index * self.offset_ns
                m = p.pending
                data = with_header_stamp(m.data, header_stamp_ns(m.data) + shift) \
                    if self.headers[m.topic] else m.data
                p.pending = RawMessage(m.topic, m.msgtype, m.timestamp_ns + shift, data)
        return p.pending

    def _play(self, now: float) -> None:
        sent: Counter[str] = Counter()
        while (m := self._next()) is not None:
            if self._t0 is None:
                self._t0 = (now, m.timestamp_ns)
            due_s = (m.timestamp_ns - self._t0[1]) / 1e9 / self.rate if self.rate > 0 else 0.0
            if due_s > now - self._t0[0]:
                return  # not due yet
            if sent[m.topic] >= self.burst:
                break
            self._pubs[m.topic].publish(m.data)
            sent[m.topic] += 1
            self.stats.counts[self.remap[m.topic]] += 1
            assert self._pass is not None
            self._pass.pending = None
        else:
            self._phase, self._phase_t = "linger", now
            self._tick(IDLE_TICK_S)
        if self.rate == 0:
            self._resume = now + sum(sent.values()) / self.drain_rate

    def flush_acks(self, timeout_s: float) -> bool:
        """Wait (bounded) until every reliable subscriber acknowledged what was published."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + timeout_s
        ok = True
        for pub in self._pubs.values():
            left = max(deadline - time.monotonic(), 0.0)
            ok = pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))) and ok
        return ok
