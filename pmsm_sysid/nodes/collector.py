"""ResultCollector: keeps the latest identification results seen on the output topics.

Subscribes to ``<ns>/model``, ``ridges``, ``validation``, ``change`` and ``diagnosis`` of
its namespace (all sporadic: one message per window or span) and keeps, per output, the last
model, ridges and validation statuses, plus the last ``keep_models`` models, ridges and
validations, the last 200 change events, the latest diagnosis and a thinned span-by-span
history of the diagnoses (bounded memory in long runs). ``run --json`` reports from it, so a process
that only runs the identification side (``--nodes identifier,gfrf``) reports the same way
as the one-process pipeline, and models can be compared across processes by ``model_id``.
"""

from __future__ import annotations

import json
from collections import deque
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.node import Node
from std_msgs.msg import String

from ..core.online.history import RunHistory
from ..diagnosed import DiagnosisHistory
from ..topics import CHANGE, DEFAULT_NAMESPACE, DIAGNOSIS, MODEL, RIDGES, VALIDATION
from .monitor import diagnostic_dicts

DEPTH = 50


class ResultCollector(Node):
    """Latest model/ridges/validation per output and the change events, from the topics."""

    def __init__(self, *, context: Context | None = None, namespace: str = DEFAULT_NAMESPACE,
                 node_name: str = "pmsm_results", keep_models: int = 256) -> None:
        # no parameters to serve: fewer entities in every wait of the shared executor
        super().__init__(node_name, context=context, namespace=namespace,
                         start_parameter_services=False)
        self.models: dict[str, dict[str, Any]] = {}
        self.model_log: deque[dict[str, Any]] = deque(maxlen=keep_models)
        self.ridges: dict[str, dict[str, Any]] = {}
        self.ridges_log: deque[dict[str, Any]] = deque(maxlen=keep_models)
        self.validation: dict[str, dict[str, Any]] = {}
        self.validation_log: deque[dict[str, Any]] = deque(maxlen=keep_models)
        self.changes: deque[dict[str, Any]] = deque(maxlen=200)
        self.history = RunHistory()  # window by window, for the report of the run
        self.last_diagnosis: dict[str, Any] | None = None
        self.diagnosis_history = DiagnosisHistory()  # span by span, for the report
        self.counts = dict.fromkeys(("model", "ridges", "validation", "change", "diagnosis"),
                                    0)
        self.create_subscription(String, MODEL, self._on_model, DEPTH)
        self.create_subscription(String, RIDGES, self._on_ridges, DEPTH)
        self.create_subscription(DiagnosticArray, VALIDATION, self._on_validation, DEPTH)
        self.create_subscription(DiagnosticArray, CHANGE, self._on_change, DEPTH)
        self.create_subscription(String, DIAGNOSIS, self._on_diagnosis, DEPTH)

    def _on_model(self, msg: String) -> None:
        self.counts["model"] += 1
        obj = _json(msg.data)
        if obj is not None:
            self.models[str(obj.get("output"))] = obj
            self.model_log.append(obj)
            self.history.model(obj)

    def _on_ridges(self, msg: String) -> None:
        self.counts["ridges"] += 1
        obj = _json(msg.data)
        if obj is not None:
            self.ridges[str(obj.get("output"))] = obj
            self.ridges_log.append(obj)
            self.history.ridges(obj)

    def _on_validation(self, msg: DiagnosticArray) -> None:
        self.counts["validation"] += 1
        for s in diagnostic_dicts(msg):
            self.validation[s["name"]] = s
            self.validation_log.append(s)
            self.history.validation(s)

    def _on_change(self, msg: DiagnosticArray) -> None:
        self.counts["change"] += 1
        for s in diagnostic_dicts(msg):
            self.changes.append(s)
            self.history.change(s)


    def _on_diagnosis(self, msg: String) -> None:
        self.counts["diagnosis"] += 1
        obj = _json(msg.data)
        if obj is not None:
            self.last_diagnosis = obj
            self.diagnosis_history.add(obj)


def _json(text: str) -> dict[str, Any] | None:
    try:
        obj = json.loads(text)
    except ValueError:
        return None
    return obj if isinstance(obj, dict) else None
