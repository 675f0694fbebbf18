"""Motor side and identification side as two processes on one host, found over DDS.

``run --nodes sim`` (sim clock, real-time rate) and ``run --nodes identifier,gfrf --record``
run as two subprocesses on the test's own ROS domain; the models they publish (read back
from the recording) equal the models of the same sim + seed in one process, window by window
(windows sit on the sample-index grid of the stamps, so both cut the same windows; the motor
side, started beside the identification side, waits with ``--wait`` until that has matched
its publishers).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
REPO = Path(__file__).resolve().parents[1]
PLANT = REPO / "plants" / "nominal_noisy.yaml"
SECONDS = 6.0
INPUTS = ("/pmsm/thrust", "/pmsm/speed", "/pmsm/position")
CLI = [sys.executable, "-m", "pmsm_sysid.cli", "run"]


def _models_from_bag(bag: Path) -> dict[str, dict[str, Any]]:
    from rosbags.highlevel import AnyReader

    from pmsm_sysid.bagio import typestore

    out = {}
    with AnyReader([bag], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == "/pmsm/model"]
        for conn, _, raw in reader.messages(connections=conns):
            m = json.loads(reader.deserialize(raw, conn.msgtype).data)
            out[m["model_id"]] = m
    return out


def _recorded_inputs(bag: Path) -> int:
    """Input messages the recorder has committed (metadata.yaml is rewritten at each flush)."""
    import yaml

    try:
        info: Any = yaml.safe_load((bag / "metadata.yaml").read_text())
        topics = info["rosbag2_bagfile_information"]["topics_with_message_count"]
        return sum(int(t["message_count"]) for t in topics
                   if t["topic_metadata"]["name"] in INPUTS)
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return 0


class _Lines:
    """Reads a process's stderr in a thread (a full pipe would stall the process)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        assert proc.stderr is not None
        stream = proc.stderr
        self.thread = threading.Thread(target=lambda: self.lines.extend(iter(stream.readline, "")),
                                       daemon=True)
        self.thread.start()

    def wait_for(self, text: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(text in line for line in list(self.lines)):
                return
            time.sleep(0.1)
        raise AssertionError(f"no '{text}' from the process: {''.join(self.lines)}")


def test_two_processes_give_the_one_process_models(ros_context: Any, ros_env: int,
                                                   tmp_path: Path) -> None:
    from pmsm_sysid.app import build_pipeline
    from pmsm_sysid.core.physics.plant import load_plant

    env = {**os.environ, "ROS_DOMAIN_ID": str(ros_env), "ROS_LOG_DIR": str(tmp_path / "log"),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    bag, summary = tmp_path / "ident", tmp_path / "ident.json"
    # every window is compared below, so none may be skipped: a queue of 8 windows (4 s at
    # this pace) holds them while the identifier's fit worker starts, or its thread waits
    # for a core, on a busy machine (the default of 1 keeps only the newest)
    ident = subprocess.Popen([*CLI, "--nodes", "identifier,gfrf", "--outputs", "speed",
                              "--set", "identifier.queue_size=8",
                              "--record", str(bag), "--json", str(summary)],
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        err_lines = _Lines(ident)
        # started beside it: the motor side publishes nothing before both subscribers of the
        # identification side (identifier, recorder) have matched its publishers
        sim = subprocess.Popen([*CLI, "--nodes", "sim", "--clock", "sim", "--rate", "1",
                                "--wait", "60", "--subscribers", "2",
                                "--excitation", "broadband",
                                "--plant", str(PLANT), "--seed", "7", "--duration",
                                str(SECONDS), "--json", str(tmp_path / "sim.json")],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        try:
            err_lines.wait_for("running", 120)  # the identification side spins
            _, sim_err = sim.communicate(timeout=120)
        finally:
            if sim.poll() is None:
                sim.kill()
                sim.wait()
        assert sim.returncode == 0, sim_err
        # stop it as a user would, once the last samples have arrived (the recorder has them)
        deadline = time.monotonic() + 120
        while _recorded_inputs(bag) < 3 * SECONDS * 500 and time.monotonic() < deadline:
            time.sleep(0.2)
        ident.send_signal(signal.SIGTERM)
        ident.wait(timeout=120)
        err_lines.thread.join(10)
        err = "".join(err_lines.lines)
    finally:
        if ident.poll() is None:
            ident.kill()
    assert ident.returncode == 0, err
    s = json.loads(summary.read_text())
    published = json.loads((tmp_path / "sim.json").read_text())["samples_published"]
    assert published == SECONDS * 500
    # the sim waits until the identification side has matched its publishers: all arrive
    assert s["samples_received"] == published
    assert s["samples_dropped"] == 0 and s["samples_missing"] == 0
    assert s["windows_skipped"] == 0
    remote = _models_from_bag(bag)
    assert len(remote) == s["models_published"] == 8

    with build_pipeline(["sim", "identifier"], plant=load_plant(PLANT), seed=7, clock="sim",
                        excitation="broadband",
                        context=ros_context, identifier_params={"outputs": ["speed"]}) as pipe:
        pipe.run(SECONDS)
        pipe.finish()
        local = {m["model_id"]: m for m in pipe.nodes["collector"].model_log}

    assert len(local) == 8  # windows ending at 1250, 1500, ..., 3000
    assert set(remote) == set(local)
    for key in sorted(local):
        a, b = local[key], remote[key]
        assert a["window"] == b["window"]
        assert [t["name"] for t in a["terms"]] == [t["name"] for t in b["terms"]]
        np.testing.assert_array_equal([t["estimate"] for t in a["terms"]],
                                      [t["estimate"] for t in b["terms"]])
