"""Small rclpy helpers shared by the nodes and the ROS verbs.

- :func:`ros_session`: a private rclpy Context (on ``ROS_DOMAIN_ID`` from the environment
  unless given) with one ``SingleThreadedExecutor``; on exit it shuts down in the safe order
  (executor, nodes, context).
- :func:`stop_on_signals`: SIGINT/SIGTERM set a stop event instead of raising, so a verb can
  leave its spin loop and finalise its output (a bag, a JSON file) cleanly.
- Stamp and message helpers: nanoseconds <-> ``builtin_interfaces/Time``, the standard three
  stamped messages <-> floats, message classes from rosbag2 type names.
- :class:`SampleEncoder`: one sample's three messages (and ``/clock``) as CDR bytes, cheaper
  to publish than messages.
- :func:`data_qos`: the QoS of the data topics (reliable, keep-last 1000).
"""

from __future__ import annotations

import importlib
import os
import signal
import struct
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import FrameType
from typing import Any, TypeVar

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown

from .core.errors import BagError, PmsmSysidError
from .dds import use_packaged_profile
from .topics import INPUT_TYPES, POSITION, SPEED, THRUST, normalize_namespace

NS_PER_S = 1_000_000_000
N = TypeVar("N", bound=Node)
DATA_DEPTH = 1000
#: keep-last depth where no sample may be lost to a peer starved of CPU for a while (20 s at
#: 500 Hz): the sim's and the replay's publishers, the identifier's and the recorder's inputs
SLACK_DEPTH = 10000


def data_qos(depth: int = DATA_DEPTH) -> QoSProfile:
    """QoS of the data topics: reliable, volatile, keep-last ``depth`` (default 1000).

    1000 samples = 2 s at 500 Hz of slack for a slow subscriber before the oldest sample is
    overwritten; a keep-last reliable publisher is compatible with any reliable or
    best-effort subscriber.
    """
    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def check_namespace(namespace: str) -> str:
    """``namespace`` normalised (``"a/"`` -> ``"/a"``, ``""`` -> ``"/"``) and checked by
    the ROS 2 rules; PmsmSysidError naming the problem."""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    ns = normalize_namespace(namespace)
    try:
        validate_namespace(ns)
    except InvalidNamespaceException as exc:
        first = str(exc).splitlines()[0].rstrip(":")
        raise PmsmSysidError(f"--namespace '{namespace}' is not a ROS 2 namespace: "
                             f"{first}") from exc
    return ns


def env_domain_id() -> int | None:
    """``ROS_DOMAIN_ID`` from the environment, or None (rcl's default 0) when unset."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError as exc:
        raise PmsmSysidError(f"ROS_DOMAIN_ID must be an integer, got '{text}'") from exc
    if not 0 <= value <= 232:
        raise PmsmSysidError(f"ROS_DOMAIN_ID must be in 0..232, got {value}")
    return value


@dataclass
class RosSession:
    """A private Context with its executor; nodes added here are destroyed on exit."""

    context: Context
    executor: SingleThreadedExecutor
    nodes: list[Node] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def add(self, node: N) -> N:
        """Add ``node`` to the executor (and destroy it when the session ends)."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, done: Callable[[], bool], timeout_s: float | None = None,
                   step_s: float = 0.05) -> bool:
        """Spin until ``done()`` or the stop event or ``timeout_s``; True if ``done()``."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not done():
            if self.stop.is_set() or not self.context.ok():
                return False
            if deadline is not None and time.monotonic() >= deadline:
                return False
            self.executor.spin_once(timeout_sec=step_s)
        return True

    def spin_for(self, seconds: float | None, step_s: float = 0.05) -> None:
        """Spin for ``seconds`` (None = until the stop event is set, e.g. by a signal)."""
        self.spin_until(lambda: False, seconds, step_s)


@contextmanager
def ros_session(domain_id: int | None = None,
                ros_args: Sequence[str] | None = None) -> Iterator[RosSession]:
    """Private rclpy Context + SingleThreadedExecutor, shut down in the safe order.

    ``domain_id`` defaults to ``ROS_DOMAIN_ID`` from the environment. ``ros_args``: ROS
    command-line arguments from ``--ros-args`` on (params files, ``-p``, ``-r``), parsed by
    rclpy for every node of the context; the process's own ``sys.argv`` is never parsed. No
    rclpy signal handlers are installed (combine with :func:`stop_on_signals` in a verb).
    """
    domain = env_domain_id() if domain_id is None else domain_id
    use_packaged_profile()
    ctx = Context()
    try:
        rclpy.init(context=ctx, domain_id=domain, args=["pmsm-sysid", *(ros_args or [])])
    except Exception as exc:  # rclpy raises RCLError subclasses of RuntimeError
        if ros_args:
            detail = str(exc).split(", at ")[0]
            raise PmsmSysidError(f"--ros-args not accepted by ROS 2: {detail}") from exc
        raise PmsmSysidError(f"cannot initialise ROS 2 (domain {domain}): {exc}") from exc
    executor = SingleThreadedExecutor(context=ctx)
    session = RosSession(ctx, executor)
    try:
        yield session
    finally:
        executor.shutdown(timeout_sec=2.0)
        for node in session.nodes:
            node.destroy_node()  # type: ignore[no-untyped-call]
        try_shutdown(context=ctx)


@contextmanager
def stop_on_signals(stop: threading.Event) -> Iterator[threading.Event]:
    """While active, SIGINT and SIGTERM set ``stop`` instead of killing the process.

    A second SIGINT while stopping raises KeyboardInterrupt (the user insists). Outside the
    main thread signals cannot be caught; the event is then only set by the caller.
    """
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop.is_set() and signum == signal.SIGINT:
            raise KeyboardInterrupt
        stop.set()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


# --- stamps -----------------------------------------------------------------------------

def seconds_to_ns(t: float) -> int:
    """Seconds (float) to integer nanoseconds, rounded to nearest."""
    return round(t * NS_PER_S)


def stamp_from_ns(ns: int) -> Any:
    """``builtin_interfaces/Time`` for ``ns`` nanoseconds (non-negative)."""
    from builtin_interfaces.msg import Time

    sec, nanosec = divmod(int(ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp_to_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


# --- the standard three messages ------------------------------------------------------

def message_class(type_name: str) -> Any:
    """Python class of a rosbag2 type name like ``geometry_msgs/msg/WrenchStamped``."""
    parts = type_name.split("/")
    if len(parts) != 3 or not all(parts):
        raise BagError(f"not a ROS 2 message type name: '{type_name}'")
    pkg, kind, name = parts
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as exc:
        raise BagError(f"message type '{type_name}' is not available in this installation") from exc


def make_sample_messages(stamp_ns: int, thrust: float, speed: float, position: float,
                         frame_id: str = "") -> dict[str, Any]:
    """The three messages of one sample, sharing one header stamp."""
    msgs = {sig: message_class(t)() for sig, t in INPUT_TYPES.items()}
    stamp = stamp_from_ns(stamp_ns)
    for msg in msgs.values():
        msg.header.stamp = stamp
        msg.header.frame_id = frame_id
    msgs[THRUST].wrench.force.x = float(thrust)
    msgs[SPEED].twist.linear.x = float(speed)
    msgs[POSITION].point.x = float(position)
    return msgs


def sample_value(signal_name: str, msg: Any) -> float:
    """The data field of one input message: force.x, linear.x or point.x."""
    if signal_name == THRUST:
        return float(msg.wrench.force.x)
    if signal_name == SPEED:
        return float(msg.twist.linear.x)
    if signal_name == POSITION:
        return float(msg.point.x)
    raise PmsmSysidError(f"unknown signal '{signal_name}' (expected thrust, speed or position)")


_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR, little-endian
_STAMP = struct.Struct("<iI")
_VALUE = struct.Struct("<d")


class SampleEncoder:
    """The three messages of one sample (and a ``rosgraph_msgs/Clock``) as serialized CDR
    bytes, for ``publisher.publish(bytes)``: what ``serialize_message`` gives for
    :func:`make_sample_messages` with the same ``frame_id`` (its alignment padding zeroed),
    at a fraction of the cost of publishing messages (no Python-to-C conversion per field).

    Each message is a template whose stamp and value are patched in place (little-endian
    CDR: the stamp right after the 4-byte encapsulation header, the value the first float64
    after the frame id). The layout is checked once: the patched bytes must have the length
    of ``serialize_message``'s and deserialize to the same messages; where they do not
    (``raw`` False: another middleware or byte order) the messages are serialized one by one.
    """

    def __init__(self, frame_id: str = "") -> None:
        from rclpy.serialization import serialize_message

        self.frame_id = frame_id
        self._serialize = serialize_message
        text_end = 16 + len(frame_id.encode()) + 1
        self._value_at = 4 + ((text_end - 4 + 7) & ~7)
        self._bufs = [bytearray(serialize_message(m)) for m in self._messages(0, 0, 0, 0)]
        for buf in self._bufs:  # the middleware leaves the alignment padding as it finds it
            buf[text_end:self._value_at] = bytes(self._value_at - text_end)
        self.raw = self._layout_holds()
        if not self.raw:
            self.encode, self.clock = self._serialized, self._clock_serialized  # type: ignore[method-assign]

    def _layout_holds(self) -> bool:
        from rclpy.serialization import deserialize_message
        from rosgraph_msgs.msg import Clock

        if not all(b[:4] == _ENCAPSULATION and len(b) >= self._value_at + 8
                   for b in self._bufs):
            return False
        probe = (123_456_789_012, -1.25, 2.5e-3, -3.75e-6)
        want = self._messages(*probe)
        for got, ref, msg in zip(self._patched(*probe), self._serialized(*probe), want,
                                 strict=True):
            if len(got) != len(ref) or deserialize_message(got, type(msg)) != msg:
                return False
        clock = self._clock_raw(probe[0])
        return (len(clock) == len(self._clock_serialized(probe[0]))
                and deserialize_message(clock, Clock) == Clock(clock=stamp_from_ns(probe[0])))

    def encode(self, stamp_ns: int, thrust: float, speed: float,
               position: float) -> tuple[bytes, bytes, bytes]:
        """(thrust, speed, position) messages of one sample, serialized."""
        return self._patched(stamp_ns, thrust, speed, position)

    def clock(self, stamp_ns: int) -> bytes:
        """A ``rosgraph_msgs/Clock`` at ``stamp_ns``, serialized."""
        return self._clock_raw(stamp_ns)

    def _patched(self, stamp_ns: int, thrust: float, speed: float,
                 position: float) -> tuple[bytes, bytes, bytes]:
        sec, nanosec = divmod(stamp_ns, NS_PER_S)
        at = self._value_at
        a, b, c = self._bufs
        _STAMP.pack_into(a, 4, sec, nanosec)
        _VALUE.pack_into(a, at, thrust)
        _STAMP.pack_into(b, 4, sec, nanosec)
        _VALUE.pack_into(b, at, speed)
        _STAMP.pack_into(c, 4, sec, nanosec)
        _VALUE.pack_into(c, at, position)
        return bytes(a), bytes(b), bytes(c)

    @staticmethod
    def _clock_raw(stamp_ns: int) -> bytes:
        return _ENCAPSULATION + _STAMP.pack(*divmod(stamp_ns, NS_PER_S))

    def _messages(self, stamp_ns: int, thrust: float, speed: float,
                  position: float) -> list[Any]:
        msgs = make_sample_messages(stamp_ns, thrust, speed, position, self.frame_id)
        return [msgs[THRUST], msgs[SPEED], msgs[POSITION]]

    def _serialized(self, stamp_ns: int, thrust: float, speed: float,
                    position: float) -> tuple[bytes, bytes, bytes]:
        a, b, c = (bytes(self._serialize(m))
                   for m in self._messages(stamp_ns, thrust, speed, position))
        return a, b, c

    def _clock_serialized(self, stamp_ns: int) -> bytes:
        from rosgraph_msgs.msg import Clock

        return bytes(self._serialize(Clock(clock=stamp_from_ns(stamp_ns))))
