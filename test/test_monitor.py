"""monitor: rate/gap bookkeeping without ROS, the result view, and the node on a live topic."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pmsm_sysid.core.monitoring import SysIdView, TopicStats, render_sysid, render_topics

NS = 1_000_000_000


def test_regular_stream_has_no_gaps_and_its_rates() -> None:
    """500 Hz stamps received at 100 Hz of wall time (a 5x slowed replay)."""
    s = TopicStats("/pmsm/speed")
    for k in range(400):
        s.feed(receive_s=10.0 + k / 100.0, stamp_ns=k * NS // 500, value=float(k))
    assert s.count == 400
    assert s.gaps == 0 and s.missing == 0 and s.backwards == 0
    assert s.stamp_rate_hz() == pytest.approx(500.0, rel=1e-9)
    # the 2 s window holds ~200 receive times 0.01 s apart: (n - 1) / span = 100 Hz
    assert s.rate_hz() == pytest.approx(100.0, rel=1e-9)
    assert s.last_value == 399.0


def test_gaps_count_missing_samples_and_backwards_steps() -> None:
    s = TopicStats("/pmsm/thrust")
    stamps = [k * 2_000_000 for k in range(10)]          # 2 ms period
    stamps += [stamps[-1] + 4 * 2_000_000]               # 3 samples missing
    stamps += [stamps[-1] + 2_000_000 * j for j in range(1, 5)]
    stamps += [stamps[-1] + 2_000_000 * 2]               # 1 missing (step = 2 periods)
    stamps += [stamps[-1] + 2_000_000]
    stamps += [stamps[-1]]                               # repeated stamp
    stamps += [stamps[-1] + 1_000_000]                   # 0.5 period: not a gap
    for i, st in enumerate(stamps):
        s.feed(receive_s=float(i), stamp_ns=st)
    assert s.gaps == 2
    assert s.missing == 4
    assert s.backwards == 1


def test_step_just_below_one_and_a_half_periods_is_not_a_gap() -> None:
    s = TopicStats("/x", expected_period_s=0.002)
    s.feed(0.0, 0)
    s.feed(0.1, 2_999_999)          # 1.4999995 periods
    s.feed(0.2, 2_999_999 + 3_000_001)  # 1.5000005 periods
    assert s.gaps == 1 and s.missing == 1  # round(1.5000005) - 1 = 1


def test_rate_window_forgets_old_messages() -> None:
    s = TopicStats("/x", window_s=1.0)
    for k in range(50):
        s.feed(k / 50.0)  # 50 Hz for 1 s, no stamps
    assert s.rate_hz() == pytest.approx(50.0)
    assert s.rate_hz(now_s=5.0) == 0.0  # all older than the window
    assert s.snapshot(now_s=5.0)["age_s"] == pytest.approx(5.0 - 49 / 50.0)


def test_sysid_view_parses_identify_gfrf_and_diagnostics() -> None:
    v = SysIdView(max_events=2)
    assert render_sysid(v.snapshot())[0] == "model: (none yet)"
    model = {"input": "thrust", "output": "speed", "sample_rate_hz": 500.0,
             "terms": [{"name": "y(k-1)", "estimate": 0.93, "std": 0.01, "err": 0.9},
                       {"name": "u(k-1)", "estimate": 1e-3, "std": 1e-5, "err": 0.05}],
             "validation": {"validation": {"nmse": 0.01, "r2": 0.99}}}
    v.on_model(json.dumps(model))
    v.on_ridges(json.dumps({"stable": True, "h1": {"peaks": [{"freq_hz": 16.5}]},
                            "h2": {"ridges": [{"kind": "f1+f2", "freq_hz": 33.0}]}}))
    v.on_model(json.dumps(dict(model, output="position")))
    v.on_validation([{"name": "ee", "level": 0, "message": "ok"},
                     {"name": "ue", "level": 0, "message": "ok"}])
    v.on_validation([{"name": "ue", "level": 2, "message": "out of band"}])  # replaces 'ue'
    v.on_validation([{"name": "gfrf", "level": 0, "message": "stable"}])  # another source
    for i in range(3):
        v.on_change(float(i), [{"name": "cogging", "level": 1, "message": f"event {i}"}])
    snap = v.snapshot()
    assert snap["model"]["n_terms"] == 2 and snap["model"]["output"] == "position"
    assert sorted(snap["models"]) == ["position", "speed"]
    assert [t["name"] for t in snap["models"]["speed"]["terms"]] == ["y(k-1)", "u(k-1)"]
    assert snap["ridges"] == {"stable": True, "h1": [16.5], "h2": [33.0], "h3": []}
    assert [(s["name"], s["passed"]) for s in snap["validation"]] == [
        ("ee", True), ("ue", False), ("gfrf", True)]
    assert [c["message"] for c in snap["changes"]] == ["event 1", "event 2"]
    text = "\n".join(render_sysid(snap))
    assert "y(k-1)=0.93" in text and "FAIL out of band" in text and "R2 0.99" in text
    v.on_model("not json {")
    assert v.snapshot()["model"] == {"error": "not JSON"}


def test_render_topics_has_one_line_per_topic() -> None:
    s = TopicStats("/pmsm/speed")
    for k in range(5):
        s.feed(k * 0.002, k * 2_000_000, 0.5)
    lines = render_topics([s.snapshot(0.01)])
    assert len(lines) == 2 and lines[1].startswith("/pmsm/speed") and "500.0" in lines[1]


@pytest.mark.ros
def test_monitor_node_counts_a_live_stream(ros_context: object) -> None:
    """A publisher with a deliberate 3-sample hole: the node reports count, value and gap."""
    import uuid

    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    from pmsm_sysid.nodes.monitor import MonitorNode
    from pmsm_sysid.rosutil import data_qos, make_sample_messages, message_class
    from pmsm_sysid.topics import MODEL_TOPIC, SPEED_TYPE

    ns = f"/t{uuid.uuid4().hex[:10]}"  # a namespace of its own: no cross-talk between runs
    mon = MonitorNode(context=ros_context, namespace=ns)  # type: ignore[arg-type]
    from rclpy.node import Node

    pub_node = Node("pub", context=ros_context)  # type: ignore[arg-type]
    pub = pub_node.create_publisher(message_class(SPEED_TYPE), f"{ns}/speed", data_qos())
    model_pub = pub_node.create_publisher(String, MODEL_TOPIC, 10)
    ex = SingleThreadedExecutor(context=ros_context)  # type: ignore[arg-type]
    ex.add_node(mon)
    ex.add_node(pub_node)
    try:
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() < 1 or model_pub.get_subscription_count() < 1:
            assert time.monotonic() < deadline, "monitor did not match"
            ex.spin_once(timeout_sec=0.05)
        ks = [k for k in range(60) if not 20 <= k < 23]
        for k in ks:
            pub.publish(make_sample_messages(k * 2_000_000, 0.0, 0.01 * k, 0.0)["speed"])
        model_pub.publish(String(data=json.dumps({"output": "speed", "terms": [
            {"name": "y(k-1)", "estimate": 0.5}]})))
        stats = mon.stats[f"{ns}/speed"]
        while stats.count < len(ks) or mon.view.model is None:
            assert time.monotonic() < deadline, f"received {stats.count} of {len(ks)}"
            ex.spin_once(timeout_sec=0.05)
        snap = mon.snapshot()
        speed = next(t for t in snap["topics"] if t["topic"] == f"{ns}/speed")
        assert speed["count"] == 57 and speed["gaps"] == 1 and speed["missing"] == 3
        assert speed["last_value"] == pytest.approx(0.59)
        assert speed["stamp_rate_hz"] == pytest.approx(500.0)
        assert snap["sysid"]["model"]["terms"][0]["name"] == "y(k-1)"
    finally:
        ex.shutdown()
        mon.destroy_node()
        pub_node.destroy_node()


def test_monitor_cli_once_writes_json(ros_env: int, tmp_path: Path) -> None:
    """With nothing publishing, --once still exits 0 and writes an empty snapshot."""
    out = tmp_path / "snap.json"
    proc = subprocess.run(
        [sys.executable, "-m", "pmsm_sysid.cli", "monitor", "--once", "--duration", "0.5",
         "--namespace", "/quiet", "--json", str(out)], capture_output=True, text=True,
        timeout=60)
    assert proc.returncode == 0, proc.stderr
    snap = json.loads(out.read_text())
    assert len(snap["topics"]) == 8 and snap["namespace"] == "/quiet"
    assert [t["count"] for t in snap["topics"][:3]] == [0] * 3
    assert "/quiet/thrust" in proc.stdout and "model: (none yet)" in proc.stdout


def test_monitor_cli_bad_interval_is_one_line(ros_env: int) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "pmsm_sysid.cli", "monitor", "--interval", "0"],
        capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "--interval" in proc.stderr
