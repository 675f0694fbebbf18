"""GfrfNode: GFRFs, ridges and validation statistics of each identified model, live.

Lives in the pipeline's namespace ``<ns>`` (node ``<ns>/pmsm_gfrf``; topic names relative to
it). Subscribes to ``<ns>/model`` (std_msgs/String, the identify JSON of one window plus
``window``, ``model_id``, ``output``). The subscription callback only hands the raw string to
a bounded latest-wins queue (``queue_size``, default 2: the newest speed and position
models; a model replaced before it was analysed is counted as skipped); a worker thread
passes it to a worker process of the node's own (parameter ``worker: process``, the
default; ``thread`` analyses in the thread), which parses it and runs
:func:`pmsm_sysid.core.frequency.analysis.analyse_json` (H1 peaks, H2/H3 ridges, poles,
support by the excitation): off the executor and off its GIL, at a lower scheduling
priority than the fits (an analysis may be skipped, a fit should not). A timer publishes
finished results from the executor thread (layouts in :mod:`.gfrf_msgs`):

* ``<ns>/ridges`` (std_msgs/String): the gfrf JSON + ``model_id``/``output``/``window``;
* ``<ns>/ridge_frequencies`` (std_msgs/Float64MultiArray): one row per peak/ridge;
* ``<ns>/validation`` (diagnostic_msgs/DiagnosticArray): status
  ``gfrf/validation/<output>`` with the model's validation statistics.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, String

from ..core.errors import DataError, GfrfError
from ..core.frequency.message import MessageAnalyser, analyse_message
from ..core.online.fitqueue import FitWorker, LatestQueue
from ..core.online.workerproc import ProcessWorker
from ..topics import DEFAULT_NAMESPACE, MODEL, MODEL_DEPTH, RIDGE_FREQUENCIES, RIDGES, VALIDATION
from .gfrf_msgs import ridges_message, validation_message
from .health import HealthPublisher, gfrf_health
from .numbers import NumberPublisher
from .params import GFRF_SPECS, check_orders, declare_all

DEFAULTS: dict[str, Any] = {"queue_size": 2, "orders": [1, 2, 3], "publish_period_s": 0.05,
                            "worker": "process"}
__all__ = ["DEFAULTS", "GfrfNode", "analyse_message"]
NICE = 10  # the analyses yield the CPU to the fits and the data path (they may skip models)
_Item = tuple[str, float]  # (raw JSON, monotonic time received)


class GfrfNode(Node):
    """Model messages in; ridges, ridge frequencies and validation statistics out."""

    def __init__(self, *, context: Context | None = None, namespace: str = DEFAULT_NAMESPACE,
                 node_name: str = "pmsm_gfrf",
                 parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        p = declare_all(self, DEFAULTS, GFRF_SPECS)
        try:
            self.orders = check_orders(p["orders"])
        except DataError as exc:
            raise GfrfError(str(exc)) from exc
        self._lock = threading.Lock()
        self._done: deque[dict[str, Any]] = deque(maxlen=16)
        self._errors: deque[str] = deque(maxlen=20)
        self.received = 0
        self.published = 0
        self.last_ridges: dict[str, Any] | None = None
        self.last_validation: dict[str, Any] | None = None
        orders = self.orders
        if p["worker"] not in ("process", "thread"):
            raise GfrfError(f"parameter worker must be 'process' or 'thread' (got "
                            f"'{p['worker']}')")
        self.queue: LatestQueue[_Item] = LatestQueue(int(p["queue_size"]))
        self.analyser: Callable[[str], dict[str, Any]] = (
            ProcessWorker[str, dict[str, Any]](MessageAnalyser, (orders,), nice=NICE)
            if p["worker"] == "process" else MessageAnalyser(orders))
        analyser = self.analyser
        self.worker: FitWorker[_Item, dict[str, Any]] = FitWorker(
            self.queue, lambda item: analyser(item[0]), self._finished,
            on_error=self._failed, latency_of=lambda item: item[1], name="gfrf-worker",
            cpu_clock=lambda: time.thread_time() + float(getattr(analyser, "cpu_s", 0.0)))
        self._ridges_pub = self.create_publisher(String, RIDGES, 10)
        self._array_pub = self.create_publisher(Float64MultiArray, RIDGE_FREQUENCIES, 10)
        self._val_pub = self.create_publisher(DiagnosticArray, VALIDATION, 10)
        self.numbers = NumberPublisher(self)
        self.health = HealthPublisher(self, "gfrf", gfrf_health(self))
        # as deep as the identifier's publisher: a burst of models it publishes at once is
        # received whole, and what is not analysed is skipped in the queue (counted)
        self.create_subscription(String, MODEL, self._on_model, MODEL_DEPTH)
        self._timer = self.create_timer(float(p["publish_period_s"]), self.publish_results)
        self.worker.start()

    def _on_model(self, msg: String) -> None:
        self.received += 1
        self.queue.put((msg.data, time.monotonic()))

    def _finished(self, _item: _Item, result: dict[str, Any]) -> None:
        with self._lock:
            self._done.append(result)

    def _failed(self, _item: _Item, exc: Exception) -> None:
        with self._lock:
            self._errors.append(str(exc))

    def publish_results(self) -> None:
        """Publish what the worker finished (timer callback; also call at shutdown)."""
        with self._lock:
            done, self._done = list(self._done), deque(maxlen=16)
            errors, self._errors = list(self._errors), deque(maxlen=20)
        for e in errors:
            self.get_logger().warning(  # type: ignore[no-untyped-call]
                f"model not analysed: {e}")
        for r in done:
            gfrf, model = r["gfrf"], r["model"]
            self._ridges_pub.publish(String(data=json.dumps(gfrf, allow_nan=False)))
            self._array_pub.publish(ridges_message(gfrf))
            self.numbers.ridges(gfrf)
            self._val_pub.publish(validation_message(model, gfrf, self._stamp(model)))
            self.last_ridges = gfrf
            self.last_validation = model.get("validation")
            self.published += 1

    def _stamp(self, model: dict[str, Any]) -> Any:
        from ..rosutil import stamp_from_ns

        end = (model.get("window") or {}).get("end_stamp")
        return stamp_from_ns(round(float(end) * 1e9)) if end is not None else None

    def summary(self) -> dict[str, Any]:
        """Counters and the latest results (the ``run --json`` summary's GFRF part)."""
        st = self.worker.stats
        return {"models_received": self.received, "models_skipped": self.queue.skipped,
                "models_analysed": st.processed - st.failed, "models_failed": st.failed,
                "ridges_published": self.published, "last_ridges": self.last_ridges,
                "last_validation": self.last_validation}

    def destroy_node(self) -> None:
        self.worker.stop()
        close = getattr(self.analyser, "close", None)
        if close is not None:
            close()
        super().destroy_node()  # type: ignore[no-untyped-call]
