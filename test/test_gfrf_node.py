"""GfrfNode: a model on <ns>/model gives the offline gfrf result on the output topics."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.frequency.analysis import analyse_json
from pmsm_sysid.core.selection.identifiability import excitation_summary
from pmsm_sysid.nodes.gfrf_msgs import (
    COLUMNS_LABEL,
    KIND_CODES,
    OK,
    WARN,
    ridge_rows,
    rows_from_flat,
    validation_values,
)

REPO = Path(__file__).resolve().parents[1]
TESTS = {name: {"max_abs": 0.05, "band": 0.062, "pass": True}
         for name in ("ee", "ue", "u2e", "u2e2", "e_eu")}
VALIDATION = {"estimation": {"nmse": 0.0012, "r2": 0.9988, "osa_r2": 0.99995},
              "validation": None, "correlation_tests": TESTS, "free_run_diverged": False}


def model_message(seq: int = 7, excitation: bool = True) -> dict[str, Any]:
    d = json.loads((REPO / "examples" / "paper_table2_speed.json").read_text())
    d.update({"window": {"seq": seq, "start_stamp": 2.0 + seq, "end_stamp": 4.0 + seq},
              "model_id": f"speed/{seq}", "fit_time_ms": 12.5, "validation": VALIDATION})
    if excitation:
        k = np.arange(1000)
        d["excitation"] = excitation_summary(50 * np.sin(2 * np.pi * 16.5 * k / 500),
                                             500.0).to_dict()
    return d


def without_timing(d: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in d.items() if k not in ("timing_ms", "analysis_time_ms")}


# ------------------------------------------------------------------ pure layouts
def test_ridge_rows_roundtrip_and_codes() -> None:
    offline = analyse_json(model_message()).to_dict()
    rows = ridge_rows(offline)
    n1 = len(offline["h1"]["peaks"])
    assert len(rows) == n1 + len(offline["h2"]["ridges"]) + len(offline["h3"]["ridges"])
    back = rows_from_flat([x for r in rows for x in r])
    assert back[0]["order"] == 1 and back[0]["kind"] == "resonance"
    assert back[0]["freq_hz"] == offline["h1"]["peaks"][0]["freq_hz"]
    assert back[0]["supported"] == 0.0  # the tone at 16.5 Hz: not supported
    r2 = back[n1]
    assert r2["order"] == 2 and r2["kind"] == offline["h2"]["ridges"][0]["kind"]
    assert r2["gain_db"] == offline["h2"]["ridges"][0]["level_db"]
    assert all(k in COLUMNS_LABEL for k in KIND_CODES)
    unchecked = ridge_rows(analyse_json(model_message(excitation=False), orders=(1,)).to_dict())
    assert {r[6] for r in unchecked} == {-1.0}


def test_validation_values_levels() -> None:
    level, msg, values = validation_values(model_message(), {"stable": True})
    assert level == OK and values["r2"] == "0.9988" and values["osa_r2"] == "0.99995"
    assert values["corr.ee.pass"] == "true" and values["corr.u2e.band"] == "0.062"
    bad = model_message()
    bad["validation"] = json.loads(json.dumps(VALIDATION))
    bad["validation"]["correlation_tests"]["ue"]["pass"] = False
    level, msg, _ = validation_values(bad, {"stable": False})
    assert level == WARN and "ue fails" in msg and "unstable" in msg
    level, msg, values = validation_values({"terms": []}, None)
    assert level == WARN and "no validation statistics" in msg and values == {}


# ------------------------------------------------------------------ live node
def spin_until(executor: Any, cond: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if cond():
            return True
    return False


@pytest.mark.ros
def test_node_publishes_the_offline_result(ros_context: Any) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray, String

    from pmsm_sysid.nodes.gfrf_node import GfrfNode
    from pmsm_sysid.topics import DEFAULT_NAMESPACE, topic_name

    def full(name: str) -> str:
        return topic_name(DEFAULT_NAMESPACE, name)

    node = GfrfNode(context=ros_context)
    probe = Node("gfrf_probe", context=ros_context)
    got: dict[str, list[Any]] = {"ridges": [], "array": [], "validation": []}
    pub = probe.create_publisher(String, full("model"), 10)
    probe.create_subscription(String, full("ridges"), got["ridges"].append, 10)
    probe.create_subscription(Float64MultiArray, full("ridge_frequencies"), got["array"].append, 10)
    probe.create_subscription(DiagnosticArray, full("validation"), got["validation"].append, 10)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(probe)
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1
                          and node.count_publishers(full("model")) >= 1, 10.0)
        model = model_message()
        pub.publish(String(data=json.dumps(model)))
        assert spin_until(ex, lambda: all(got.values()), 30.0), {k: len(v) for k, v in got.items()}
        live = json.loads(got["ridges"][0].data)
        offline = analyse_json(model).to_dict()
        assert without_timing(live) == {**without_timing(offline), "model_id": "speed/7",
                                        "output": "speed", "window": model["window"]}
        arr = got["array"][0]
        assert arr.layout.dim[0].label == "ridges" and arr.layout.dim[1].label == COLUMNS_LABEL
        assert arr.layout.dim[0].size * arr.layout.dim[1].size == len(arr.data)
        assert list(arr.data) == [x for r in ridge_rows(offline) for x in r]
        st = got["validation"][0].status[0]
        assert st.name == "gfrf/validation/speed" and st.hardware_id == "speed/7"
        assert st.level == bytes([OK])
        kv = {v.key: v.value for v in st.values}
        assert kv["r2"] == "0.9988" and kv["corr.e_eu.max_abs"] == "0.05" and kv["stable"] == "true"
        assert got["validation"][0].header.stamp.sec == 11  # window end_stamp 11.0 s
        s = node.summary()
        assert s["models_received"] == 1 and s["ridges_published"] == 1
        assert s["last_ridges"]["model_id"] == "speed/7"
    finally:
        ex.shutdown()
        node.destroy_node()
        probe.destroy_node()
    assert not node.worker.alive


@pytest.mark.ros
def test_burst_is_latest_wins_and_bad_models_are_counted(ros_context: Any) -> None:
    """Models arriving faster than they are analysed are skipped, the newest is analysed;
    a malformed model is counted as failed and does not stop the worker."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from pmsm_sysid.nodes.gfrf_node import GfrfNode

    node = GfrfNode(context=ros_context, parameter_overrides=[Parameter("queue_size", value=1)])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    gate = threading.Event()
    original = node.worker._fn
    node.worker._fn = lambda item: (gate.wait(10.0), original(item))[1]  # hold the first
    try:
        node._on_model(String(data="{not json"))
        for seq in range(1, 6):
            node._on_model(String(data=json.dumps(model_message(seq, excitation=False))))
        gate.set()
        assert spin_until(ex, lambda: node.summary()["last_ridges"] is not None
                          and node.summary()["last_ridges"]["model_id"] == "speed/5", 30.0)
        s = node.summary()
        assert s["models_received"] == 6
        assert s["models_skipped"] >= 4  # queue of 1: at most the first and the last run
        assert s["models_failed"] + s["models_analysed"] + s["models_skipped"] == 6
        assert node.worker.alive
    finally:
        ex.shutdown()
        node.destroy_node()
    assert not node.worker.alive
