"""The recorder in a process of its own (nodes/recorder_process.py): what it counts is what
the bag holds, losses are counted, and a SIGKILLed owner leaves a finalised bag holding every
message up to the kill. Completion conditions only (message counts, files), no timing.

The owner is this test process where it stops the recorder itself (the recorder is a
process of its own all the same); a Python of its own only where it is killed."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import textwrap
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from rosbags.highlevel import AnyReader

from pmsm_sysid.core.online.workerproc import owner_alive

REPO = Path(__file__).resolve().parents[1]
N = 600
PERIOD_NS = 2_000_000

# publishes N samples once the recorder matched, waits until the recorder holds them all,
# then kills itself (no clean-up can run): _publish_and_record's owner, killed
SCRIPT = textwrap.dedent("""
    import os, signal, sys, time
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from pmsm_sysid.nodes.recorder_process import RecorderProcess
    from pmsm_sysid.rosutil import data_qos, make_sample_messages
    from pmsm_sysid.topics import INPUT_TYPES, input_topic

    bag, ns, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    ctx = Context()
    rclpy.init(context=ctx)
    node = Node("pub", context=ctx)
    first = make_sample_messages(0, 0, 0, 0)
    pubs = {s: node.create_publisher(type(first[s]), input_topic(ns, s), data_qos())
            for s in INPUT_TYPES}
    rec = RecorderProcess(bag, namespace=ns, domain_id=ctx.get_domain_id())
    print(rec._proc.pid, flush=True)
    while not all(p.get_subscription_count() for p in pubs.values()):
        time.sleep(0.01)
    for k in range(n):
        msgs = make_sample_messages(10**9 + k * 2_000_000, k, 2 * k, 3 * k)
        for s, p in pubs.items():
            p.publish(msgs[s])
    while rec.samples_recorded < n:  # everything is in the recorder's hands
        time.sleep(0.01)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def _publish_and_record(ctx: Any, bag: Path, ns: str,
                        skip: int) -> tuple[dict[str, Any], int]:
    """SCRIPT's owner in this process: N samples (every ``skip``-th one from the 4th on left
    out when ``skip``) once the recorder has matched, then stop it when it holds them all;
    the recorder's summary and the samples sent."""
    from rclpy.node import Node

    from pmsm_sysid.nodes.recorder_process import RecorderProcess
    from pmsm_sysid.rosutil import data_qos, make_sample_messages
    from pmsm_sysid.topics import INPUT_TYPES, input_topic

    node = Node(f"pub_{uuid.uuid4().hex[:6]}", context=ctx)
    first = make_sample_messages(0, 0, 0, 0)
    pubs = {s: node.create_publisher(type(first[s]), input_topic(ns, s), data_qos())
            for s in INPUT_TYPES}
    rec = RecorderProcess(bag, namespace=ns, domain_id=ctx.get_domain_id())
    try:
        deadline = time.monotonic() + 120
        while not all(p.get_subscription_count() for p in pubs.values()):
            assert time.monotonic() < deadline, "the recorder never subscribed"
            time.sleep(0.01)
        sent = 0
        for k in range(N):
            if skip and k % skip == 3:
                continue
            msgs = make_sample_messages(10**9 + k * 2_000_000, k, 2 * k, 3 * k)
            for s, p in pubs.items():
                p.publish(msgs[s])
            sent += 1
        while rec.samples_recorded < sent:  # everything is in the recorder's hands
            assert time.monotonic() < deadline, (rec.samples_recorded, sent)
            time.sleep(0.01)
        return rec.stop(), sent
    finally:
        rec.close()
        node.destroy_node()


def _run_killed(tmp_path: Path, ros_env: int, bag: Path,
                ns: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "ROS_DOMAIN_ID": str(ros_env), "ROS_LOG_DIR": str(tmp_path / "log"),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-c", SCRIPT, str(bag), ns, str(N)],
                          env=env, capture_output=True, text=True, timeout=300)


def _read(bag: Path) -> tuple[Counter[str], dict[str, list[int]]]:
    counts: Counter[str] = Counter()
    stamps: dict[str, list[int]] = {}
    with AnyReader([bag]) as reader:  # stock rosbags, no repair
        for conn, _, raw in reader.messages():
            counts[conn.topic] += 1
            if not conn.msgtype.startswith("geometry_msgs/"):
                continue
            msg = reader.deserialize(raw, conn.msgtype)
            stamps.setdefault(conn.topic, []).append(
                msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    return counts, stamps


@pytest.mark.ros
@pytest.mark.parametrize("skip", [0, 7], ids=["all", "every-7th-missing"])
def test_counts_agree_with_the_bag_and_missing_samples_are_counted(
        ros_context: Any, tmp_path: Path, skip: int) -> None:
    bag, ns = tmp_path / "bag", f"/r{uuid.uuid4().hex[:8]}"
    summary, published = _publish_and_record(ros_context, bag, ns, skip)
    counts, stamps = _read(bag)
    sent = sum(1 for k in range(N) if not (skip and k % skip == 3))
    assert published == sent
    assert summary["messages"] == sum(counts.values()) == 3 * sent
    assert summary["topics"] == dict(counts)
    missing = N - sent - (1 if skip and (N - 1) % skip == 3 else 0)  # a trailing skip is unseen
    for topic, ts in stamps.items():
        assert len(ts) == sent and ts == sorted(ts)
        assert summary["samples_missing"].get(topic, 0) == missing
        assert summary["stamp_gaps"].get(topic, 0) == (missing if skip else 0)


@pytest.mark.ros
def test_owner_killed_the_recorder_finalises_the_bag_up_to_the_kill(
        ros_env: int, tmp_path: Path) -> None:
    bag, ns = tmp_path / "bag", f"/r{uuid.uuid4().hex[:8]}"
    proc = _run_killed(tmp_path, ros_env, bag, ns)
    assert proc.returncode == -9, proc.stderr
    # the recorder sees its owner gone, takes what waits, closes the bag and ends
    recorder_pid = int(proc.stdout.split()[0])
    deadline = time.monotonic() + 120
    while owner_alive(recorder_pid):
        assert time.monotonic() < deadline, "the recorder did not end"
        time.sleep(0.1)
    assert not (bag / f"{bag.name}.db3-wal").exists()  # closed: WAL folded into the .db3
    counts, stamps = _read(bag)
    assert set(counts.values()) == {N}  # every sample sent before the kill
    for ts in stamps.values():
        assert {b - a for a, b in itertools.pairwise(ts)} == {PERIOD_NS}


@pytest.mark.ros
def test_sim_clock_paces_to_identifier_and_recorder(ros_context: Any, tmp_path: Path) -> None:
    """Stepped sim clock at hop 50 with a recording: no window skipped (one latest-wins
    slot), no sample lost, and the summary's counts are the bag's."""
    from pmsm_sysid.app import build_pipeline

    bag, ns = tmp_path / "run", f"/r{uuid.uuid4().hex[:8]}"
    with build_pipeline(["sim", "identifier"], clock="sim", context=ros_context, record=str(bag),
                        namespace=ns,
                        identifier_params={"outputs": ["speed"], "hop": 50,
                                           "queue_size": 1}) as pipe:
        pipe.run(5.0)
        pipe.finish()
        s = pipe.summary()
    counts, stamps = _read(bag)
    assert s["samples_published"] == s["samples_received"] == 2500
    assert s["windows_skipped"] == 0 and s["windows_due"] >= 25
    assert s["windows_fitted"] + s["windows_failed"] == s["windows_due"]
    assert s["record_samples_lost"] == 0 and s["record_stamp_gaps"] == 0
    assert s["recorded_messages"] == sum(counts.values())
    assert s["recorded_by_topic"] == dict(counts)
    for sig in ("thrust", "speed", "position"):
        ts = stamps[f"{ns}/{sig}"]
        assert len(ts) == 2500 and {b - a for a, b in itertools.pairwise(ts)} == {PERIOD_NS}


def test_a_recorder_whose_caller_is_gone_tells_it_nothing() -> None:
    """A caller interrupted while its recorder starts closes its end of the pipe before the
    recorder says it is ready: the recorder's message then goes nowhere, without a traceback
    (the recorder records nothing and closes its bag)."""
    import multiprocessing

    from pmsm_sysid.nodes.recorder_process import _tell

    mine, callers = multiprocessing.Pipe()
    assert _tell(mine, ("ready", None)) is True and callers.recv() == ("ready", None)
    callers.close()
    assert _tell(mine, ("ready", None)) is False
