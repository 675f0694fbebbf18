"""What a live worker process imports: the identifier's window fits and the GFRF node's
analysis of their models, run in one object that reports which heavy SciPy modules the
work imported (those its process did not hold when built: a fork server started by another
user in the same process, e.g. a fleet's, may have preloaded them). Kept apart from the test
modules, which import SciPy themselves (a worker unpickles its factory by importing the
factory's module)."""

from __future__ import annotations

import json
import sys
from typing import Any

from pmsm_sysid.core.frequency.message import analyse_message
from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config

WATCHED = ("scipy.signal", "scipy.stats")


class FitAndAnalyse:
    """``probe(window)``: how many models and cross-validations the tracker made of the
    window, how many of its models were analysed (each as the GFRF node receives it, JSON
    text), and which of :data:`WATCHED` the process holds by then and did not when built."""

    def __init__(self, params: dict[str, Any]) -> None:
        self.tracker = WindowTracker(tracker_config(params))
        self.held = {m for m in WATCHED if m in sys.modules}

    def __call__(self, window: Any) -> dict[str, Any]:
        result = self.tracker.process(window)
        analyses = [analyse_message(json.dumps(m), (1, 2, 3)) for m in result.models]
        new = [m for m in WATCHED if m in sys.modules and m not in self.held]
        return {"models": len(result.models), "validations": len(result.validations),
                "analyses": len(analyses), "loaded": new}
