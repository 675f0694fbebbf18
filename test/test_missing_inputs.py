"""A run that gets nothing says why: the expected topics, what arrived, what never came (in
its log, its JSON summary and its one-line summary); a replay nobody listens to says so."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
CLI = [sys.executable, "-m", "pmsm_sysid.cli"]
PROBLEM = "no messages on /pmsm/thrust, /pmsm/speed, /pmsm/position: nothing to identify"


def _env(ros_env: int, tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "ROS_DOMAIN_ID": str(ros_env),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOG_DIR": str(tmp_path / "log")}


def test_a_run_with_no_inputs_names_the_topics_it_waited_for(ros_env: int,
                                                             tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    proc = subprocess.run([*CLI, "run", "--nodes", "identifier,gfrf", "--duration", "4",
                           "--json", str(out)], env=_env(ros_env, tmp_path),
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert f"[pmsm.pmsm_identifier]: {PROBLEM}" in proc.stderr  # the log, after 3 s
    assert PROBLEM in proc.stdout.splitlines()[-1]  # the one-line summary
    s = json.loads(out.read_text())
    assert s["samples_received"] == 0 and s["inputs"]["problem"] == PROBLEM
    assert s["inputs"]["missing"] == ["/pmsm/thrust", "/pmsm/speed", "/pmsm/position"]
    assert s["inputs"]["arrived"] == {} and s["inputs"]["expected"] == s["inputs"]["missing"]


def test_a_replay_nobody_listens_to_says_so(ros_env: int, tmp_path: Path) -> None:
    repo = Path(__file__).resolve().parents[1]
    bag = repo / "bags" / "paper_speed_nominal"
    proc = subprocess.run([*CLI, "replay", str(bag), "--wait", "0.5", "--fast", "--json", "-"],
                          env=_env(ros_env, tmp_path), capture_output=True, text=True,
                          timeout=180)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["messages"] > 0 and set(s["subscribers"].values()) == {0}
    assert "replay: nobody listened: no subscriber on" in proc.stderr
    assert "to no subscriber" in proc.stderr  # the per-topic account (stdout is the JSON)
    bad = subprocess.run([*CLI, "replay", str(bag), "--subscribers", "0"],
                         env=_env(ros_env, tmp_path), capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--subscribers: must be >= 1" in bad.stderr
