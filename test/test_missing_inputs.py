"""A run that gets nothing says why: the expected topics, what arrived, what never came (in
its log, its JSON summary and its one-line summary); a replay nobody listens to says so.

Both verbs run in this process (``reliability_helpers.ros_verb``: stdout and stderr as
captured at the descriptors, the nodes' log lines from rcl included): what they say is
checked here, not the process."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from reliability_helpers import ros_verb

pytestmark = [pytest.mark.ros, pytest.mark.slow]
PROBLEM = "no messages on /pmsm/thrust, /pmsm/speed, /pmsm/position: nothing to identify"


def test_a_run_with_no_inputs_names_the_topics_it_waited_for(
        ros_env: int, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.json"
    proc = ros_verb(capfd, "run", "--nodes", "identifier,gfrf", "--duration", "4", "--json",
                    str(out))
    assert proc.returncode == 0, proc.stderr
    assert f"[pmsm.pmsm_identifier]: {PROBLEM}" in proc.stderr  # the log, after 3 s
    assert PROBLEM in proc.stdout.splitlines()[-1]  # the one-line summary
    s = json.loads(out.read_text())
    assert s["samples_received"] == 0 and s["inputs"]["problem"] == PROBLEM
    assert s["inputs"]["missing"] == ["/pmsm/thrust", "/pmsm/speed", "/pmsm/position"]
    assert s["inputs"]["arrived"] == {} and s["inputs"]["expected"] == s["inputs"]["missing"]


def test_a_replay_nobody_listens_to_says_so(ros_env: int,
                                            capfd: pytest.CaptureFixture[str]) -> None:
    repo = Path(__file__).resolve().parents[1]
    bag = repo / "bags" / "paper_speed_nominal"
    proc = ros_verb(capfd, "replay", str(bag), "--wait", "0.5", "--fast", "--json", "-")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["messages"] > 0 and set(s["subscribers"].values()) == {0}
    assert "replay: nobody listened: no subscriber on" in proc.stderr
    assert "to no subscriber" in proc.stderr  # the per-topic account (stdout is the JSON)
    bad = ros_verb(capfd, "replay", str(bag), "--subscribers", "0")
    assert bad.returncode == 2 and "--subscribers: must be >= 1" in bad.stderr
