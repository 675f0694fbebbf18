"""The three input topics of a drive as serialized messages: stamp and value per message.

:class:`InputIntake` subscribes to ``thrust``, ``speed`` and ``position`` (relative names in
the node's namespace, or under another namespace given in full) with the data QoS at
keep-last ``SLACK_DEPTH`` (as the identifier's own input subscriptions)
and hands each message's ``header.stamp`` and value to ``push(signal, stamp_ns, value)``,
read straight from the CDR bytes (the generic deserializer for anything else). A burst costs
one executor callback, not one per message: each callback also takes what already waits on
the three subscriptions, round robin, up to ``DRAIN_ROUNDS`` rounds.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.serialization import deserialize_message

from ..bagio.cdr import decode_stamped
from ..rosutil import SLACK_DEPTH, data_qos, message_class, sample_value, stamp_to_ns
from ..topics import INPUT_TYPES, topic_name

DRAIN_ROUNDS = 100  # at most 300 input messages taken per subscription callback


class InputIntake:
    """Raw subscriptions to one drive's input topics, decoded into ``push`` calls."""

    def __init__(self, node: Node, push: Callable[[str, int, float], None],
                 namespace: str | None = None,
                 on_message: Callable[[], None] | None = None) -> None:
        self._push = push
        self._seen = on_message or (lambda: None)
        self._types = {sig: message_class(t) for sig, t in INPUT_TYPES.items()}
        names = {sig: topic_name(namespace, sig) if namespace is not None else sig
                 for sig in INPUT_TYPES}  # relative names: remap rules apply as usual
        self.topics = {sig: node.resolve_topic_name(name) for sig, name in names.items()}
        self._subs = {sig: node.create_subscription(
            self._types[sig], names[sig], self._callback(sig), data_qos(SLACK_DEPTH), raw=True)
            for sig in INPUT_TYPES}

    def _callback(self, sig: str) -> Any:
        def callback(data: bytes) -> None:
            self._take(sig, data)
            self._drain()

        return callback

    def _take(self, sig: str, data: bytes) -> None:
        self._seen()
        got = decode_stamped(data)
        if got is None:  # not little-endian CDR: the generic deserializer
            msg = deserialize_message(data, self._types[sig])
            got = (stamp_to_ns(msg.header.stamp), sample_value(sig, msg))
        self._push(sig, *got)

    def take_pending(self) -> None:
        """Take the messages already delivered, without waiting for the executor."""
        self._drain()

    def _drain(self) -> None:
        for _ in range(DRAIN_ROUNDS):
            took = False
            for sig, sub in self._subs.items():
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, True)
                if got is not None:
                    self._take(sig, got[0])
                    took = True
            if not took:
                return
