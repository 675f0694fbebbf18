"""Shared pieces of the live-equals-offline tests: replay a bag (its own process) into an
in-process pipeline, and compare each live model with the offline fit of the same window.

:func:`fast`: the replay options for a test that compares models, not timing, of a bag whose
samples travel on ONE topic (a ``JointState``): ``--fast``, paced bursts as fast as the
subscribers' queues allow. Every queue on the way holds ``SLACK_DEPTH`` (10000) messages per
topic -- the replay's reliable publishers, the identifier's subscriptions and the
recorder's -- so a bag of at most that many messages loses none to a subscriber starved for
a while (a message the transport drops in a burst is resent: late, not lost). Not for
separate thrust/speed/position topics: the identifier joins those by stamp and gives up a
sample once 16 newer ones wait behind it, and a resent message puts its topic that far
behind the others (seen: 2500 of each arrived, 400 aligned); those replay paced (``--rate``).
The windows come faster than they are fitted: the pipeline's ``queue_size`` must hold them."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_inprocess import invoke

from pmsm_sysid.core.selection.identify import FitConfig, identify_recording
from pmsm_sysid.core.terms.model import NarxModel, Structure


def fast(n_per_topic: int) -> tuple[str, ...]:
    """The ``replay`` options for a one-topic bag of ``n_per_topic`` messages (module doc);
    that many must fit every queue on the way, else a starved subscriber could lose some."""
    from pmsm_sysid.rosutil import SLACK_DEPTH  # rclpy: only where a test replays

    assert n_per_topic <= SLACK_DEPTH, (n_per_topic, SLACK_DEPTH)
    return ("--fast",)


@dataclass(frozen=True)
class Replayed:
    summary: dict[str, Any]
    models: list[dict[str, Any]]
    ridges: dict[str, dict[str, Any]]
    replay_out: str


def replay_into_pipeline(bag: Path, env: dict[str, str], ctx: Any, n_samples: int, *,
                         replay_args: tuple[str, ...] = (), deadline_s: float = 180,
                         **pipeline: Any) -> Replayed:
    """``replay BAG`` in its own process into identifier + GFRF nodes on ``ctx`` (None: a
    context of the pipeline's own, e.g. with ``ros_args`` and ``domain_id``); returns once
    the replay ended and the identifier holds ``n_samples`` (completion conditions; the
    deadline only stops a hung run)."""
    from pmsm_sysid.app import build_pipeline

    with build_pipeline(["identifier", "gfrf"], context=ctx, **pipeline) as pipe:
        replay = subprocess.Popen(
            [sys.executable, "-m", "pmsm_sysid.cli", "replay", str(bag), *replay_args],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + deadline_s
            pipe.run(until=lambda: replay.poll() is not None or time.monotonic() > deadline)
            pipe.run(until=lambda: pipe.identifier.engine.samples_received >= n_samples
                     or time.monotonic() > deadline)
        finally:
            if replay.poll() is None:
                replay.kill()
            out, err = replay.communicate()
        assert replay.returncode == 0, err
        pipe.finish()
        collector = pipe.nodes["collector"]
        return Replayed(pipe.summary(), list(collector.model_log),
                        {r["model_id"]: r for r in collector.ridges_log}, out)


def write_joint_state_bag(rec: Any, path: Path, *, topic: str = "/joint_states",
                          joints: tuple[str, ...] = ("axis",), axis: str = "axis") -> Path:
    """``rec`` as ros2_control's joint_state_broadcaster records it: one
    ``sensor_msgs/JointState`` per sample on ``topic`` with every joint of ``joints``, the
    axis's ``effort``/``velocity``/``position`` = thrust/speed/position (the other joints
    carry other values), written with the stock ``rosbags`` typestore only."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    js, header, time_t = (store.types[n] for n in (
        "sensor_msgs/msg/JointState", "std_msgs/msg/Header", "builtin_interfaces/msg/Time"))
    k = joints.index(axis)
    stamps = np.round(np.asarray(rec.t) * 1e9).astype(np.int64)
    with Writer(path, version=9) as w:
        conn = w.add_connection(topic, "sensor_msgs/msg/JointState", typestore=store)
        for i, ns in enumerate(stamps.tolist()):
            values = [np.full(len(joints), 0.5 * i) for _ in range(3)]
            for arr, v in zip(values, (rec.position[i], rec.speed[i], rec.thrust[i]),
                              strict=True):
                arr[k] = v
            msg = js(header=header(stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9),
                                   frame_id=""),
                     name=list(joints), position=values[0], velocity=values[1],
                     effort=values[2])
            w.write(conn, ns, store.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
    return path


def assert_live_equals_offline(model: dict[str, Any], rec: Any, a: int, b: int) -> dict[str, Any]:
    """The live model of window [a, b) has the offline fit's terms, estimates, ERRs and R2
    (to 1e-9); returns the offline fit's JSON."""
    st = model["structure"]
    cfg = FitConfig(structure=Structure(st["ny"], st["nu"], st["degree"], st["delay"]),
                    method=model["method"])
    ref = identify_recording(rec, output=model["output"], config=cfg, estimate=(a, b),
                             validate=None, form=model["form"]).to_dict()
    assert [t["name"] for t in model["terms"]] == [t["name"] for t in ref["terms"]], \
        model["model_id"]
    got, want = NarxModel.from_dict(model), NarxModel.from_dict(ref)
    np.testing.assert_allclose(got.estimates, want.estimates, rtol=1e-9, atol=0)
    np.testing.assert_allclose(got.err, want.err, rtol=1e-9, atol=1e-15)
    assert model["validation"]["estimation"]["r2"] == pytest.approx(
        ref["validation"]["estimation"]["r2"], rel=1e-9)
    return ref


def assert_identify_verb_agrees(bag: Path, model: dict[str, Any], a: int, env: dict[str, str],
                                out: Path) -> dict[str, Any]:
    """``pmsm-sysid identify BAG --estimate a:a+n`` (in this process: an offline verb) gives
    the live model's terms and estimates; returns the verb's JSON."""
    b = a + model["window"]["n_samples"]
    proc = invoke("identify", str(bag), "--estimate", f"{a}:{b}", "--no-validate", "--method",
                  model["method"], "--json", str(out), env=env)
    assert proc.returncode == 0, proc.stderr
    cli: dict[str, Any] = json.loads(out.read_text())
    assert [t["name"] for t in cli["terms"]] == [t["name"] for t in model["terms"]]
    np.testing.assert_allclose([t["estimate"] for t in cli["terms"]],
                               [t["estimate"] for t in model["terms"]], rtol=1e-9, atol=0)
    return cli
