"""MonitorNode: subscribes to the package's topics and keeps :mod:`core.online.monitoring` stats.

The node lives in the watched namespace ``<ns>`` (``<ns>/pmsm_monitor``) and subscribes to
relative names, so it sees that pipeline only. Inputs (``<ns>/thrust|speed|position``) are
subscribed with the data QoS (reliable, keep-last 1000) so that the monitor itself does not
create gaps; the identification outputs (``<ns>/model``, ...) with reliable keep-last 10.
Both match reliable publishers of any depth and durability.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String

from ..core.online.monitoring import SysIdView, TopicStats
from ..rosutil import data_qos, message_class, sample_value, stamp_to_ns
from ..topics import (
    CHANGE,
    DEFAULT_NAMESPACE,
    DIAGNOSIS,
    INPUT_TYPES,
    MODEL,
    RIDGE_FREQUENCIES,
    RIDGES,
    VALIDATION,
    normalize_namespace,
)
from .health import HealthPublisher, monitor_health


def diagnostic_dicts(msg: Any) -> list[dict[str, Any]]:
    """DiagnosticArray statuses as plain dicts (level as int, values as a str mapping)."""
    out = []
    for s in msg.status:
        level = s.level
        out.append({
            "name": s.name, "message": s.message, "hardware_id": s.hardware_id,
            "level": int.from_bytes(level, "little") if isinstance(level, bytes) else int(level),
            "values": {kv.key: kv.value for kv in s.values},
        })
    return out


def _summary(text: str, limit: int = 48) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


class MonitorNode(Node):
    """Subscribes to the input topics and the identification outputs; no publishers."""

    def __init__(self, *, context: Context | None = None, namespace: str = DEFAULT_NAMESPACE,
                 node_name: str = "pmsm_monitor",
                 now: Callable[[], float] = time.monotonic) -> None:
        super().__init__(node_name, context=context, namespace=namespace)
        self._now = now
        self.namespace = normalize_namespace(self.get_namespace())
        self.stats: dict[str, TopicStats] = {}
        self.view = SysIdView()
        for signal, type_name in INPUT_TYPES.items():
            topic = self.resolve_topic_name(signal)
            self.stats[topic] = TopicStats(topic, type_name)
            self.create_subscription(message_class(type_name), signal,
                                     self._input_callback(topic, signal), data_qos())
        outputs: list[tuple[str, Any, Callable[[Any], None]]] = [
            (MODEL, String, lambda m: self.view.on_model(m.data)),
            (RIDGES, String, lambda m: self.view.on_ridges(m.data)),
            (RIDGE_FREQUENCIES, Float64MultiArray,
             lambda m: self.view.on_ridge_frequencies(list(m.data))),
            (VALIDATION, DiagnosticArray,
             lambda m: self.view.on_validation(diagnostic_dicts(m))),
            (CHANGE, DiagnosticArray,
             lambda m: self.view.on_change(stamp_to_ns(m.header.stamp) / 1e9,
                                           diagnostic_dicts(m))),
            (DIAGNOSIS, String, lambda m: self.view.on_diagnosis(m.data)),
        ]
        for name, cls, handler in outputs:
            type_name = f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
            topic = self.resolve_topic_name(name)
            self.stats[topic] = TopicStats(topic, type_name)
            self.create_subscription(cls, name, self._output_callback(topic, handler), 10)
        self.health = HealthPublisher(self, "monitor", monitor_health(self))

    def _input_callback(self, topic: str, signal: str) -> Callable[[Any], None]:
        stats = self.stats[topic]

        def callback(msg: Any) -> None:
            stats.feed(self._now(), stamp_to_ns(msg.header.stamp), sample_value(signal, msg))

        return callback

    def _output_callback(self, topic: str, handler: Callable[[Any], None]) -> Callable[[Any], None]:
        stats = self.stats[topic]

        def callback(msg: Any) -> None:
            # Outputs are sporadic (one per fitted window): no stamp-gap bookkeeping.
            value = _summary(msg.data) if isinstance(msg, String) else type(msg).__name__
            stats.feed(self._now(), None, value)
            handler(msg)

        return callback

    def snapshot(self) -> dict[str, Any]:
        """JSON-ready state: per-topic stats and the latest identification results."""
        now = self._now()
        return {"namespace": self.namespace,
                "topics": [s.snapshot(now) for s in self.stats.values()],
                "sysid": self.view.snapshot()}
