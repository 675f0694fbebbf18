"""``pmsm-sysid run --diagnose`` as a user runs it: the summary's diagnosis keys, the one-line
headline, the report's figure; a bad plant file or namespace is one line and exit 2 before
any node starts (in this process: the exit status is ``main``'s)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from reliability_helpers import ros_verb

pytestmark = pytest.mark.ros
CLI = [sys.executable, "-m", "pmsm_sysid.cli"]


def _env(ros_env: int, tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "ROS_DOMAIN_ID": str(ros_env),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOG_DIR": str(tmp_path / "log")}


@pytest.mark.parametrize(("args", "match"), [
    (["--diagnose", "no_such_plant.yaml"], "no_such_plant.yaml: no such plant file"),
    (["--diagnose", "{plant}"], "unknown key"),
    (["--diagnose-sim", "/a//b"], "empty name part"),
    (["--diagnose-sim", "/pmsm"], "that is the drive's own namespace"),
    (["--set", "diagnose.period_s=5"], "the diagnosis needs a reference"),
    (["--nodes", "sim,diagnose"], "the diagnosis needs a reference"),
    (["--diagnose", "nominal", "--set", "diagnose.span_s=0.5"], "span_s"),
])
def test_a_bad_reference_is_one_line_and_exit_2(args: list[str], match: str, ros_env: int,
                                                tmp_path: Path,
                                                capfd: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("mass_kg: 2.0\nwheels: 4\n")
    # in this process; a warning is printed as a process prints it: one more line
    proc = ros_verb(capfd, "run", "--clock", "sim", "--duration", "1",
                    *[a.replace("{plant}", str(bad)) for a in args])
    code, out, err = proc.returncode, proc.stdout, proc.stderr
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and match in lines[0], err
    assert "running" not in err and not out


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_run_with_a_live_diagnosis_reports_it(ros_env: int, tmp_path: Path,
                                              capfd: pytest.CaptureFixture[str]) -> None:
    """In this process (the run ends by itself; its exit status is ``main``'s, stdout and
    stderr as captured at the descriptors): one Python and its imports fewer."""
    out, rep = tmp_path / "run.json", tmp_path / "report"
    proc = ros_verb(capfd, "run", "--clock", "sim", "--duration", "20", "--diagnose",
                    "plants/nominal.yaml", "--set", "diagnose.span_s=10", "--set",
                    "diagnose.period_s=10", "--json", str(out), "--report", str(rep))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(out.read_text())
    assert s["nodes"] == ["sim", "identifier", "gfrf", "diagnose"]
    assert s["diagnoses_run"] == s["diagnoses_due"] == 2
    assert s["diagnoses_skipped"] == s["diagnoses_failed"] == 0
    last = s["last_diagnosis"]
    assert last["effects"] == [] and last["reference"] == "plant_file"
    assert last["plant_file"] == "plants/nominal.yaml"
    assert last["window"]["end_stamp"] == pytest.approx(19.998)
    assert last["window"]["samples"] == 5000 and last["counts"]["diagnoses_run"] == 2
    assert {"mismatch", "fit", "corrected_plant", "held_out"} <= set(last)
    assert s["diagnose"]["span_s"] == 10.0 and s["diagnose"]["sample_rate_hz"] == 500.0
    assert len(s["history"]["diagnosis"]["rows"]) == 2
    assert s["verdict"]["status"] == "pass", s["verdict"]
    assert "; latest diagnosis: nothing missing (2 run, 0 skipped)" in proc.stdout
    assert (rep / "run_diagnosis.png").is_file()
    assert "Live run: diagnosis over time" in (rep / "index.html").read_text()
    # no stale-input warning although the sim waited for the diagnoses
    assert "stale input" not in proc.stderr


def test_the_diagnose_executable_refuses_a_bad_reference(ros_env: int, tmp_path: Path) -> None:
    exe = Path(sys.executable).parent / "diagnose"
    for args, match in ((["-p", "plant_file:=no_such.yaml"], "no_such.yaml: no such plant file"),
                        ([], "exactly one reference")):
        proc = subprocess.run([str(exe), "--ros-args", *args], env=_env(ros_env, tmp_path),
                              capture_output=True, text=True, timeout=120)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and match in lines[0], proc.stderr


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_diagnose_executable_diagnoses_the_drive_it_listens_to(
        ros_env: int, tmp_path: Path, ros_context: Any, ros_executor: Any,
        sim_motor: Any) -> None:
    """``ros2 run pmsm_sysid diagnose --ros-args -r __ns:=/d1 -p plant_file:=nominal``: the
    node alone in its process, diagnosing a drive on /d1 (here the simulated one, 2 s spans)
    and publishing on /d1/diagnosis; SIGTERM ends it cleanly."""
    import signal

    from rclpy.node import Node
    from std_msgs.msg import String

    from pmsm_sysid.testing import spin_until

    got: list[dict[str, Any]] = []
    probe = Node("probe", context=ros_context)
    probe.create_subscription(String, "/d1/diagnosis", lambda m: got.append(json.loads(m.data)),
                              10)
    ros_executor.add_node(probe)
    exe = Path(sys.executable).parent / "diagnose"
    proc = subprocess.Popen([str(exe), "--ros-args", "-r", "__ns:=/d1", "-p",
                             "plant_file:=nominal", "-p", "span_s:=2.0", "-p", "period_s:=2.0"],
                            env=_env(ros_env, tmp_path), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        spin_until(ros_executor, lambda: probe.count_publishers("/d1/diagnosis") > 0,
                   timeout_s=120)
        sim_motor(namespace="/d1", plant="drive", excitation="broadband")
        spin_until(ros_executor, lambda: len(got) >= 1, timeout_s=600)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
        ros_executor.remove_node(probe)
        probe.destroy_node()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert "/d1/pmsm_diagnose" in err
    d = got[0]
    assert d["reference"] == "plant_file" and d["plant_file"] == "nominal"
    assert d["window"]["samples"] == 1000 and d["window"]["sample_rate_hz"] == pytest.approx(500)
