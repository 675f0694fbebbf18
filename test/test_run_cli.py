"""``pmsm-sysid run`` as a user runs it: summary JSON, clean SIGTERM, one-line errors.

The run sent SIGTERM is a process of its own, started by a module fixture; the five-second
run (it ends by itself: its exit status is ``main``'s) runs in this process meanwhile, as
do the refused inputs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.ros
CLI = [sys.executable, "-m", "pmsm_sysid.cli"]
KEYS = {"samples_received", "samples_dropped", "windows_fitted", "windows_skipped",
        "last_model", "last_ridges", "last_validation", "change_events"}


def _env(ros_env: int, tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "ROS_DOMAIN_ID": str(ros_env),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOG_DIR": str(tmp_path / "log")}


@dataclass(frozen=True)
class Runs:
    """The module's run sent SIGTERM, a process started (on a ROS domain of its own) before
    the five-second run, which mostly waits for real time, runs in this process."""

    sigterm: Future[tuple[int, str, Path, Path]]  # exit code, stderr, bag, summary JSON


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runs]:
    from pmsm_sysid.testing.pytest_plugin import next_domain_id

    tmp = tmp_path_factory.mktemp("runs")
    (tmp / "sigterm").mkdir()
    with ThreadPoolExecutor(1) as pool:
        yield Runs(pool.submit(_sigterm_mid_run, next_domain_id(), tmp / "sigterm"))


@pytest.mark.slow
@pytest.mark.xdist_group("run_cli")
def test_run_for_five_seconds_prints_the_summary(runs: Runs, ros_env: int,
                                                 capfd: pytest.CaptureFixture[str]) -> None:
    from reliability_helpers import ros_verb

    proc = ros_verb(capfd, "run", "--duration", "5", "--json", "-")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert set(s) >= KEYS
    assert s["nodes"] == ["sim", "identifier", "gfrf"] and s["clock"] == "wall"
    # --duration counts samples of data (5 s at 500 Hz), whatever the machine's speed
    assert s["samples_published"] == 2500
    assert s["samples_received"] == s["samples_published"]
    assert s["samples_dropped"] == 0 and s["samples_missing"] == 0
    assert s["windows_fitted"] + s["windows_skipped"] == s["windows_due"] >= 4
    m = s["last_model"]
    assert m["output"] == "speed" and m["input"] == "thrust" and m["terms"]
    assert {"structure", "validation", "window", "fit_time_ms", "model_id"} <= set(m)
    assert s["last_ridges"]["output"] == "speed"
    assert {"h1", "h2", "poles", "stable"} <= set(s["last_ridges"])
    assert "pmsm-sysid run:" in proc.stderr
    # --duration stops the motor through its max_samples parameter: not a change to report
    # (it was logged as "parameters changed: ['max_samples']" though the user changed nothing)
    assert "parameters changed" not in proc.stderr
    assert s["verdict"]["status"] in ("pass", "warning", "FAIL")
    assert set(s["verdict"]["windows"]) <= {"speed", "position"}


def _sigterm_mid_run(domain: int, tmp_path: Path) -> tuple[int, str, Path, Path]:
    """``run --record`` sent SIGTERM once at least 1000 samples and two models are committed
    to the bag."""
    bag, out = tmp_path / "live", tmp_path / "run.json"
    proc = subprocess.Popen([*CLI, "run", "--record", str(bag), "--json", str(out)],
                            env=_env(domain, tmp_path), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (_recorded(bag) > 3000
                                                   and _recorded(bag, "/pmsm/model") >= 2):
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, err, bag, out


@pytest.mark.slow
@pytest.mark.xdist_group("run_cli")
def test_sigterm_mid_run_finalises_the_recording(runs: Runs) -> None:
    from rosbags.highlevel import AnyReader

    from pmsm_sysid.bagio import read_recording

    returncode, err, bag, out = runs.sigterm.result(timeout=300)
    assert returncode == 0, err
    assert "Traceback" not in err
    s = json.loads(out.read_text())
    assert s["stopped_by_signal"] is True and set(s) >= KEYS
    with AnyReader([bag]) as reader:  # plain rosbags, no project code
        counts: dict[str, int] = {}
        for conn, _, _ in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    assert sum(counts.values()) == s["recorded_messages"]
    rec = read_recording(bag)
    n = len(rec.recording)
    inputs = [counts[f"/pmsm/{s}"] for s in ("thrust", "speed", "position")]
    # stopped between the three messages of a sample: at most the last sample is partial
    assert n >= 1000 and max(inputs) - min(inputs) <= 3 and min(inputs) - 3 <= n <= min(inputs)
    assert counts.get("/pmsm/model", 0) == s["models_published"] >= 2


def _recorded(bag: Path, topic: str | None = None) -> int:
    """Messages committed to the bag so far (on ``topic``, or in all)."""
    meta = bag / "metadata.yaml"
    if not meta.exists():
        return 0
    import yaml

    try:
        info: Any = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        if topic is None:
            return int(info["message_count"])
        return sum(int(t["message_count"]) for t in info["topics_with_message_count"]
                   if t["topic_metadata"]["name"] == topic)
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return 0


@pytest.mark.parametrize("argv,match", [
    (["--duration", "-1"], "--duration: must be > 0"),
    (["--nodes", "sim,motor"], "--nodes"),
    (["--plant", "no/such/plant.yaml"], "plant"),
    (["--rate", "2"], "--rate applies to --clock sim"),
    (["--set", "identifier.windw=5", "--duration", "1"], "no parameter"),
    (["--set", "cogging.enabled=true"], "NODE.PARAM=VALUE"),
])
def test_bad_input_is_one_line_and_exit_2(ros_env: int, capfd: pytest.CaptureFixture[str],
                                          argv: list[str], match: str) -> None:
    """Refused before any work, so run in this process (reliability_helpers.ros_verb);
    stderr as captured at the descriptor, rcl's own output included."""
    from reliability_helpers import ros_verb

    proc = ros_verb(capfd, "run", *argv)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and match in lines[0] and "Traceback" not in proc.stderr


def test_existing_record_path_is_refused(ros_env: int, tmp_path: Path,
                                         capfd: pytest.CaptureFixture[str]) -> None:
    from reliability_helpers import ros_verb

    bag = tmp_path / "bag"
    bag.mkdir()
    proc = ros_verb(capfd, "run", "--record", str(bag), "--duration", "1")
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_help_says_what_the_false_alarm_bench_measured() -> None:
    """run --help states the change detector's false alarms as docs/online.md's hour-long
    table measured them (it said 'a few false alarms per hour' under prbs and aprbs after
    the bench showed none): quiet under every excitation only while every row is 0."""
    import re

    from pmsm_sysid.cli.run import EPILOG

    table = (Path(__file__).resolve().parents[1] / "docs" / "online.md").read_text()
    rows = re.findall(r"^\| ([a-z-]+) \| (speed|position) \| \d+ \| [^|]+ \| (\d+) \|", table,
                      flags=re.M)
    assert len(rows) >= 14 and {r[0] for r in rows} >= {"prbs", "aprbs", "broadband"}
    assert all(int(r[2]) == 0 for r in rows)
    text = " ".join(EPILOG.split())
    assert "quiet under every packaged excitation" in text
    assert "false alarms per hour" not in text
    assert "1 window in 20" in text and "binomial" in text
