"""``pmsm-sysid run --diagnose`` as a user runs it: the summary's diagnosis keys, the one-line
headline, the report's figure; a bad plant file or namespace is one line and exit 2 before
any node starts."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

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
                                                tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("mass_kg: 2.0\nwheels: 4\n")
    argv = [*CLI, "run", "--clock", "sim", "--duration", "1",
            *[a.replace("{plant}", str(bad)) for a in args]]
    proc = subprocess.run(argv, env=_env(ros_env, tmp_path), capture_output=True, text=True,
                          timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and match in lines[0], proc.stderr
    assert "running" not in proc.stderr and not proc.stdout


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_run_with_a_live_diagnosis_reports_it(ros_env: int, tmp_path: Path) -> None:
    out, rep = tmp_path / "run.json", tmp_path / "report"
    proc = subprocess.run(
        [*CLI, "run", "--clock", "sim", "--duration", "20", "--diagnose", "plants/nominal.yaml",
         "--set", "diagnose.span_s=10", "--set", "diagnose.period_s=10", "--json", str(out),
         "--report", str(rep)],
        env=_env(ros_env, tmp_path), capture_output=True, text=True, timeout=840)
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
