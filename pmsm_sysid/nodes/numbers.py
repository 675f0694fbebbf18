"""Plottable numbers: one standard message per quantity on ``<ns>/stats/<output>/<quantity>``.

Why these types: Foxglove and PlotJuggler plot any numeric field of any message, but only
of message types they can decode without this package's interfaces, and one curve per topic
is what their topic browsers offer directly. So each quantity has its own topic with the
plainest standard type: ``std_msgs/Float64`` (``data``) for values, ``std_msgs/Int32`` for
the term count, ``std_msgs/Float64MultiArray`` for the variable-length list of ridge
frequencies (plotted as ``data[0]``, ``data[1]``, ...). These carry no header: viewers plot
them against receive time, which is within one fit of the window's end on a live run (the
JSON on ``<ns>/model`` keeps the window's stamps for exact timing). The quantities, types and
units are :data:`pmsm_sysid.topics.STAT_TOPICS` (listed in the README). NaN = no value for
this window (e.g. the change score while the detector is still learning).
"""

from __future__ import annotations

import math
from typing import Any

from rclpy.node import Node
from std_msgs.msg import Float64, Float64MultiArray, Int32

from .. import diagnosed
from ..topics import (
    DIAGNOSIS_COUNTS,
    DIAGNOSIS_STATS,
    FLOAT64_ARRAY_TYPE,
    FLOAT64_TYPE,
    INT32_TYPE,
    STAT_TOPICS,
    stat_topic,
)
from .gfrf_msgs import ridge_rows

_CLASSES = {INT32_TYPE: Int32, FLOAT64_ARRAY_TYPE: Float64MultiArray}
JUDGED = ("steady", "change")  # detector states with a meaningful score


def _float(value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        return math.nan
    return out


class NumberPublisher:
    """Publishers of ``stats/<output>/<quantity>`` made on first use (relative names)."""

    def __init__(self, node: Node, depth: int = 10) -> None:
        self.node, self.depth = node, depth
        self._pubs: dict[str, Any] = {}

    def _publisher(self, output: str, quantity: str) -> Any:
        name = stat_topic(output, quantity)
        if name not in self._pubs:
            spec = STAT_TOPICS.get(quantity) or DIAGNOSIS_COUNTS.get(quantity)
            cls = _CLASSES.get(spec[0] if spec else FLOAT64_TYPE, Float64)
            self._pubs[name] = self.node.create_publisher(cls, name, self.depth)
        return self._pubs[name]

    def publish(self, output: str, quantity: str, value: Any) -> None:
        pub = self._publisher(output, quantity)
        if pub.msg_type is Int32:
            pub.publish(Int32(data=int(value)))
        elif pub.msg_type is Float64MultiArray:
            pub.publish(Float64MultiArray(data=[float(v) for v in value]))
        else:
            pub.publish(Float64(data=_float(value)))

    # -- what the identifier publishes --------------------------------------------------
    def model(self, model: dict[str, Any]) -> None:
        self.publish(str(model["output"]), "terms", len(model["terms"]))

    def validation(self, v: dict[str, Any]) -> None:
        fr = v["free_run"]
        self.publish(str(v["output"]), "free_run_r2", fr["r2"])
        self.publish(str(v["output"]), "free_run_nrmse", fr["nrmse"])

    def decision(self, d: dict[str, Any]) -> None:
        score = d.get("score") if d.get("state") in JUDGED else None
        self.publish(str(d["output"]), "change_statistic", score)

    # -- what the GFRF node publishes ---------------------------------------------------
    def ridges(self, gfrf: dict[str, Any]) -> None:
        output = str(gfrf.get("output") or "model")
        peaks = [p for p in gfrf["h1"]["peaks"] if p.get("gain_db") is not None]
        top = max(peaks, key=lambda p: p["gain_db"]) if peaks else None
        self.publish(output, "h1_peak_hz", top["freq_hz"] if top else None)
        self.publish(output, "h1_peak_gain_db", top["gain_db"] if top else None)
        self.publish(output, "ridge_frequencies_hz", [row[3] for row in ridge_rows(gfrf)])

    # -- what the diagnosis node publishes ----------------------------------------------
    def prepare_diagnosis(self) -> None:
        """Create the diagnosis's publishers now (they exist before the first result)."""
        for quantity in diagnosed.numbers({}):
            self._publisher(DIAGNOSIS_STATS, quantity)

    def diagnosis(self, d: dict[str, Any]) -> None:
        """Every effect's numbers (NaN when not named), the counts and the held-out fit."""
        for quantity, value in diagnosed.numbers(d).items():
            self.publish(DIAGNOSIS_STATS, quantity, value)
