"""simulate -> bag -> replay -> record -> bag keeps every message bit for bit; loop; SIGTERM."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import ExcitationSource
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant

REPO = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "pmsm_sysid.cli"]
NS = 1_000_000_000


def _unique_ns() -> str:
    """A namespace of its own, so test runs side by side on one host cannot cross-talk."""
    return f"/t{uuid.uuid4().hex[:10]}"


def _make_bag(path: Path, n: int, seed: int = 5, storage: str = "mcap") -> Any:
    from pmsm_sysid.bagio import write_recording

    plant = load_plant(REPO / "plants" / "nominal_noisy.yaml")
    rec = simulate(plant, ExcitationSource("multisine", 500.0, seed=seed).block(0, n), seed=seed)
    write_recording(path, rec, storage=storage)
    return rec


def _raw(path: Path) -> dict[str, list[bytes]]:
    """topic -> CDR bytes in log order, read with plain rosbags (no project code)."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list[bytes]] = {}
    with AnyReader([path]) as reader:
        for conn, _, data in reader.messages():
            out.setdefault(conn.topic, []).append(bytes(data))
    return out


def _stamps_values(path: Path, topic: str) -> tuple[list[int], list[Any]]:
    from rosbags.highlevel import AnyReader

    stamps, msgs = [], []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, data in reader.messages(connections=conns):
            msg = reader.deserialize(data, conn.msgtype)
            stamps.append(msg.header.stamp.sec * NS + msg.header.stamp.nanosec)
            msgs.append(msg)
    return stamps, msgs


def _run_in_process(ctx: Any, bag: Path, out: Path, expected: int, **replay: Any) -> Any:
    """Replayer and recorder as nodes on one SingleThreadedExecutor."""
    from rclpy.executors import SingleThreadedExecutor

    from pmsm_sysid.bagio import BagRecorder
    from pmsm_sysid.nodes.recorder import RecorderNode
    from pmsm_sysid.nodes.replayer import ReplayerNode

    ex = SingleThreadedExecutor(context=ctx)
    with BagRecorder(out) as recorder:
        rec_node = RecorderNode(recorder, context=ctx, namespace=replay["namespace"],
                                topics=replay.pop("record_topics", None))
        rep_node = ReplayerNode(bag, context=ctx, settle_s=0.0, linger_s=0.1, **replay)
        ex.add_node(rec_node)
        ex.add_node(rep_node)
        try:
            deadline = time.monotonic() + 60
            while not (rep_node.finished and rec_node.total >= expected):
                assert time.monotonic() < deadline, f"recorded {rec_node.total} of {expected}"
                ex.spin_once(timeout_sec=0.05)
        finally:
            ex.shutdown()
            rep_node.destroy_node()
            rec_node.destroy_node()
    return rep_node


@pytest.mark.ros
def test_round_trip_in_process_is_bit_for_bit(ros_context: Any, tmp_path: Path) -> None:
    from pmsm_sysid.bagio import read_recording

    n, ns = 1500, _unique_ns()
    rec = _make_bag(tmp_path / "sim", n)
    topics = [f"{ns}/{s}" for s in ("position", "speed", "thrust")]
    rep = _run_in_process(ros_context, tmp_path / "sim", tmp_path / "rec", 3 * n, rate=0.0,
                          namespace=ns, record_topics=topics)
    assert rep.stats.matched and rep.stats.passes == 1
    original, recorded = _raw(tmp_path / "sim"), _raw(tmp_path / "rec")
    assert sorted(recorded) == topics
    for topic, msgs in original.items():
        got = recorded[topic.replace("/pmsm", ns)]
        assert len(got) == n == len(msgs)
        assert got == msgs, topic          # every CDR byte, in order
    back = read_recording(tmp_path / "rec").recording
    assert np.array_equal(back.t, rec.t) and np.array_equal(back.speed, rec.speed)
    assert np.array_equal(back.thrust, rec.thrust)
    assert np.array_equal(back.position, rec.position)


@pytest.mark.ros
def test_loop_shifts_stamps_and_paced_replay_keeps_schedule(ros_context: Any,
                                                            tmp_path: Path) -> None:
    """Two passes at 4x under a new namespace: stamps keep increasing by exactly one period."""
    n, rate, ns = 200, 4.0, _unique_ns()
    _make_bag(tmp_path / "sim", n, storage="sqlite3")
    start = time.monotonic()
    rep = _run_in_process(ros_context, tmp_path / "sim", tmp_path / "rec", 2 * 3 * n,
                          rate=rate, loops=2, namespace=ns)
    elapsed = time.monotonic() - start
    assert rep.stats.passes == 2
    # paced: the second pass cannot start before (2n - 1) periods / rate of playback
    assert elapsed >= (2 * n - 1) * 0.002 / rate
    assert rep.offset_ns == n * 2_000_000   # span (n-1) periods + one period
    orig_stamps, orig = _stamps_values(tmp_path / "sim", "/pmsm/speed")
    stamps, msgs = _stamps_values(tmp_path / "rec", f"{ns}/speed")
    assert len(stamps) == 2 * n
    assert np.all(np.diff(stamps) == 2_000_000)      # strictly increasing, no seam
    assert stamps[:n] == orig_stamps
    assert [m.twist.linear.x for m in msgs] == [m.twist.linear.x for m in orig] * 2
    assert {m.header.frame_id for m in msgs} == {"pmsm"}


@pytest.mark.ros
def test_header_stamp_patch_equals_reserialisation() -> None:
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import serialize_message

    from pmsm_sysid.nodes.replayer import header_stamp_ns, with_header_stamp

    msg = WrenchStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    msg.header.frame_id = "pmsm"
    msg.wrench.force.x = -1.25
    data = serialize_message(msg)
    assert header_stamp_ns(data) == 12 * NS + 345
    msg.header.stamp.sec, msg.header.stamp.nanosec = 7, 999_999_999
    assert with_header_stamp(data, 7 * NS + 999_999_999) == serialize_message(msg)


@pytest.mark.ros
def test_topics_without_a_python_type_are_skipped() -> None:
    from pmsm_sysid.nodes.replayer import has_header, publishable, remap_topics

    ok, skipped = publishable({"/pmsm_sysid/model_typed": "pmsm_sysid/msg/NarxModel",
                               "/pmsm/speed": "geometry_msgs/msg/TwistStamped",
                               "/pmsm_sysid/model": "std_msgs/msg/String"})
    assert skipped == {"/pmsm_sysid/model_typed": "pmsm_sysid/msg/NarxModel"}
    assert has_header(ok["/pmsm/speed"]) and not has_header(ok["/pmsm_sysid/model"])
    assert remap_topics(ok, "/axis2") == {"/pmsm/speed": "/axis2/speed",
                                          "/pmsm_sysid/model": "/pmsm_sysid/model"}
    # the pipeline's results and plottable numbers move with its inputs
    ours = {"/pmsm/speed": "geometry_msgs/msg/TwistStamped", "/pmsm/model": "std_msgs/msg/String",
            "/pmsm/stats/speed/terms": "std_msgs/msg/Int32", "/other/x": "std_msgs/msg/String"}
    assert remap_topics(ours, "/b") == {"/pmsm/speed": "/b/speed", "/pmsm/model": "/b/model",
                                        "/pmsm/stats/speed/terms": "/b/stats/speed/terms",
                                        "/other/x": "/other/x"}


def _env(domain: int, tmp: Path) -> dict[str, str]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(tmp / "ros_log"), PYTHONUNBUFFERED="1")
    return env


@pytest.mark.ros
@pytest.mark.slow
def test_cli_replay_to_record_and_sigterm_finalises(ros_env: int, tmp_path: Path) -> None:
    """Two processes: `record` (stopped by SIGTERM) and `replay --fast` of a simulated bag.
    Both start at once: the replay publishes nothing before the recorder has subscribed to
    every topic (it waits for that, up to --wait)."""
    n, ns = 2000, _unique_ns()
    _make_bag(tmp_path / "sim", n)
    env = _env(ros_env, tmp_path)
    topics = [f"{ns}/{s}" for s in ("position", "speed", "thrust")]
    recorder = subprocess.Popen([*CLI, "record", "--out", str(tmp_path / "rec"),
                                 "--topics", *topics], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    replay = subprocess.Popen([*CLI, "replay", str(tmp_path / "sim"), "--fast", "--wait", "120",
                               "--namespace", ns, "--json", "-"],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert recorder.stdout is not None
        first = recorder.stdout.readline()      # printed once the subscriptions exist
        assert first.startswith(f"recording {', '.join(topics)} into"), first
        replayed, replay_err = replay.communicate(timeout=180)
        assert replay.returncode == 0, replay_err
        sent = json.loads(replayed)
        assert sent["matched"] and sent["messages"] == 3 * n
        recorder.send_signal(signal.SIGTERM)
        out, err = recorder.communicate(timeout=30)
    finally:
        for proc in (recorder, replay):
            if proc.poll() is None:
                proc.kill()
    assert recorder.returncode == 0, err
    assert f"recorded {tmp_path / 'rec'}: {3 * n} messages" in out
    original, recorded = _raw(tmp_path / "sim"), _raw(tmp_path / "rec")   # plain AnyReader
    moved = {t.replace("/pmsm", ns): msgs for t, msgs in original.items()}
    assert {t: len(m) for t, m in recorded.items()} == {t: n for t in moved}
    assert recorded == moved


@pytest.mark.ros
def test_cli_errors_are_one_line(ros_env: int, tmp_path: Path,
                                 capfd: pytest.CaptureFixture[str]) -> None:
    """Refused before any work: in this process (reliability_helpers.ros_verb)."""
    from reliability_helpers import ros_verb

    cases = [
        (["replay", str(tmp_path / "missing")], "no such bag"),
        (["replay", str(REPO / "README.md")], "not a rosbag2"),
        (["replay", str(tmp_path), "--rate", "-1"], "--rate: must be >= 0"),
        (["record", "--out", str(REPO / "README.md")], "exists already"),
        (["record", "--out", str(tmp_path / "x"), "--duration", "0"], "--duration"),
    ]
    for argv, text in cases:
        proc = ros_verb(capfd, *argv)
        assert proc.returncode == 2, (argv, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and text in lines[0], (argv, proc.stderr)


@pytest.mark.ros
def test_a_starved_recorder_keeps_every_message_received_before_the_stop(
        ros_context: Any, tmp_path: Path) -> None:
    """The recorder's executor never spins while 3000 samples arrive (a starved process):
    what it stores at the stop is every message received before it, and no more than the
    first one after it on each topic; the count is set by the queue, not by a clock."""
    from rclpy.node import Node

    from pmsm_sysid.bagio import BagRecorder
    from pmsm_sysid.nodes.recorder import RecorderNode
    from pmsm_sysid.rosutil import data_qos, message_class
    from pmsm_sysid.topics import SPEED_TYPE

    ns, n_before, n_after = _unique_ns(), 3000, 40
    with BagRecorder(tmp_path / "rec") as recorder:
        rec_node = RecorderNode(recorder, context=ros_context, namespace=ns,
                                topics=[f"{ns}/speed"])
        pub_node = Node("starved_pub", context=ros_context)
        pub = pub_node.create_publisher(message_class(SPEED_TYPE), f"{ns}/speed", data_qos())
        try:
            deadline = time.monotonic() + 30   # discovery, then publish into the queue
            while pub.get_subscription_count() < 1:
                assert time.monotonic() < deadline, "the recorder never subscribed"
                time.sleep(0.01)
            msg = message_class(SPEED_TYPE)()
            for k in range(n_before):
                msg.header.stamp.nanosec = k * 2_000_000 % NS
                msg.header.stamp.sec = k * 2_000_000 // NS
                pub.publish(msg)
            assert pub.wait_for_all_acked()
            stop_ns = time.time_ns()
            time.sleep(0.01)
            for _ in range(n_after):
                pub.publish(msg)
            assert pub.wait_for_all_acked()
            assert rec_node.total == 0                 # nothing spun: all of it is queued
            stored = rec_node.take_received_before(stop_ns)
        finally:
            pub_node.destroy_node()
            rec_node.destroy_node()
    assert stored == n_before + 1
    assert len(_raw(tmp_path / "rec")[f"{ns}/speed"]) == n_before + 1
