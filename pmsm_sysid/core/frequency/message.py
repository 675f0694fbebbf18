"""What the GFRF node does with one model message (pure; runs in its worker process).

:func:`analyse_message` parses the identify JSON of one window's model and runs
:func:`.gfrf_analysis.analyse_json` on it; :class:`MessageAnalyser` is the same with the
orders fixed, in a form a worker process can build (:class:`.workerproc.ProcessWorker`).
"""

from __future__ import annotations

import json
import time
from typing import Any

from ..errors import GfrfError, PmsmSysidError
from .analysis import analyse_json


def analyse_message(text: str, orders: tuple[int, ...] = (1, 2, 3)) -> dict[str, Any]:
    """``{"gfrf": ridges JSON + model_id/output/window/analysis_time_ms, "model": model}``
    of one model message; GfrfError if it is not a model."""
    t0 = time.perf_counter()
    try:
        model = json.loads(text)
    except ValueError as exc:
        raise GfrfError(f"model message is not JSON: {exc}") from exc
    if not isinstance(model, dict):
        raise GfrfError("model message is not a JSON object")
    try:
        res = analyse_json(model, orders=orders).to_dict()
    except PmsmSysidError as exc:
        raise GfrfError(f"model {model.get('model_id', '?')}: {exc}") from exc
    res.update({"model_id": model.get("model_id"), "output": model.get("output"),
                "window": model.get("window"),
                "analysis_time_ms": 1e3 * (time.perf_counter() - t0)})
    return {"gfrf": res, "model": model}


class MessageAnalyser:
    """``analyse_message(text, orders)`` as a callable object (picklable by reference)."""

    def __init__(self, orders: tuple[int, ...] = (1, 2, 3)) -> None:
        self.orders = tuple(orders)

    def __call__(self, text: str) -> dict[str, Any]:
        return analyse_message(text, self.orders)
