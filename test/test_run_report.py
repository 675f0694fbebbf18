"""The report of a live run: the run summary keeps a bounded window-by-window history built
from the published results, and the page draws it over time."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_inprocess import invoke
from test_report import REPO, check_page

from pmsm_sysid.core.online.history import RunHistory
from pmsm_sysid.report.build import report_summary

RUN_FIGURES = {"run_fit", "run_terms", "run_h1", "run_change", "run_latency"}
GFRF_FIGURES = {"h1", "h2_contour", "h2_surface", "h3_slice"}


def _window(seq: int) -> dict[str, Any]:
    return {"seq": seq, "start_stamp": seq * 0.5 - 2.0, "end_stamp": seq * 0.5}


def _validation(output: str, seq: int, r2: float, score: float) -> dict[str, Any]:
    """A cross-validation status as the monitor/collector sees it (values as strings)."""
    return {"name": f"identifier/cross_validation/{output}", "level": 0, "values": {
        "r2": str(r2), "nrmse": str(np.sqrt(1 - r2)), "diverged": "false",
        "validated_on": json.dumps(_window(seq)), "change_score": str(score),
        "change_state": "steady", "change_threshold": "7.0"}}


def test_history_rows_meet_by_window_and_stay_bounded() -> None:
    h = RunHistory(max_rows=16)
    for seq in range(40):
        for out in ("speed", "position"):
            # results arrive in any order: validation before model for odd windows
            v = _validation(out, seq, 0.9 + seq / 1000, float(seq % 9))
            m = {"output": out, "window": _window(seq), "fit_time_ms": 10.0 + seq,
                 "terms": [{"name": "y(k-1)"}, {"name": f"u(k-{1 + seq % 3})"}]}
            for item in ((v, m) if seq % 2 else (m, v)):
                (h.validation if "name" in item else h.model)(item)
        if seq == 20:
            h.change({"name": "identifier/change/speed", "values": {
                "window": json.dumps(_window(seq)), "reasons": '["xval_nrmse"]'}})
    h.ridges({"output": "speed", "window": _window(38), "h1": {"peaks": [
        {"freq_hz": 16.5, "gain_db": 40.0}, {"freq_hz": 50.0, "gain_db": 45.0}]}})
    d = h.to_dict()
    rows = d["outputs"]["speed"]
    assert len(rows) <= 16 and d["stride"]["speed"] == 4  # thinned twice: whole run kept
    assert rows[0]["seq"] == 0 and rows[-1]["seq"] == 36
    assert all(r["seq"] % 4 == 0 for r in rows)
    last = rows[-1]
    assert last["t"] == 18.0 and last["n_terms"] == 2 and last["terms"] == ["y(k-1)", "u(k-1)"]
    assert last["r2"] == pytest.approx(0.936) and last["fit_ms"] == 46.0
    assert last["change_score"] == 0.0 and d["change_threshold"] == 7.0
    assert d["events"] == [{"output": "speed", "seq": 20, "t": 10.0, "reasons": ["xval_nrmse"]}]
    # seq 38 is not kept at stride 4: its H1 does not make a row of its own
    assert all(r["seq"] != 38 for r in rows)
    json.dumps(d, allow_nan=False)


@pytest.mark.ros
@pytest.mark.slow
def test_run_report_draws_the_history(tmp_path: Path, ros_env: int,
                                      capfd: pytest.CaptureFixture[str]) -> None:
    """run --report on a short simulated run, then 'report SUMMARY.json' of the same run.
    The run ends by itself and what is checked is its files, not its process: it runs in
    this process (a Python and its imports fewer, about 1.5 s of CPU)."""
    from reliability_helpers import ros_verb

    out = tmp_path / "rep"
    summary = tmp_path / "run.json"
    r = ros_verb(capfd, "run", "--clock", "sim", "--duration", "12", "--json", str(summary),
                 "--report", str(out))
    assert r.returncode == 0, r.stderr[-2000:]
    d = json.loads(summary.read_text())
    hist = d["history"]
    assert set(hist["outputs"]) == {"speed", "position"}
    fitted = [r for rows in hist["outputs"].values() for r in rows if "n_terms" in r]
    # every fitted window of the run has its row (none thinned in a short run)
    assert len(fitted) == d["models_published"] > 0
    assert any("r2" in r and "change_score" in r for r in fitted)
    check_page(out / "index.html", RUN_FIGURES | GFRF_FIGURES)
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "models over time" in page and "fit latency" in page
    again = tmp_path / "again"
    r = invoke("report", str(summary), "--out", str(again), cwd=REPO)  # an offline verb
    assert r.returncode == 0, r.stderr[-2000:]
    check_page(again / "index.html", RUN_FIGURES | GFRF_FIGURES)


@pytest.mark.ros
def test_run_report_refuses_a_file_as_directory(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    r = subprocess.run([sys.executable, "-m", "pmsm_sysid.cli", "run", "--clock", "sim",
                        "--duration", "1", "--report", str(f)], capture_output=True,
                       text=True, timeout=120, cwd=REPO)
    assert r.returncode == 2 and "--report" in r.stderr
    assert r.stderr.strip().count("\n") == 0


def test_summary_without_model_still_reports(tmp_path: Path) -> None:
    res = report_summary({"nodes": ["sim"], "last_model": None, "history": None},
                         tmp_path / "rep")
    assert res.figures == () and "no window-by-window history" in res.index.read_text()


def _text(page: str) -> str:
    """The page's words, tags and markup stripped."""
    import html
    import re

    page = re.sub(r"<(style|script)[^>]*>.*?</\1>", " ", page, flags=re.S)
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", page)).split())


def test_the_run_page_reads_right_for_a_wall_clock_run(tmp_path: Path) -> None:
    """A wall-clock run's last model: its window by its clock time (its sample indices count
    from 1970 and mean nothing), a heading that says which model it is, the run's verdict
    and its windows judged together, '1 pole' for a first-order model."""
    import pmsm_sysid as ps

    fit = ps.identify("bags/paper_speed_nominal", ny=1, nu=2, degree=1, terms=2,
                      estimate=(1000, 2000), validate=None)
    model = fit.to_dict()
    model.pop("source", None)
    start = 1_795_665_361.0  # epoch stamps, as the wall clock gives them
    model["estimate"] = [897_832_680_500, 897_832_681_500]
    model["window"] = {"seq": 13, "start_stamp": start, "end_stamp": start + 1.998,
                       "start_index": 897_832_680_500, "stop_index": 897_832_681_500,
                       "n_samples": 1000}
    summary = {"nodes": ["sim", "identifier"], "clock": "wall", "last_model": model,
               "history": None, "validation_counts": {"speed": [50, 52]},
               "verdict": {"status": "pass", "failures": [], "warnings": [],
                           "outputs": ["speed validation pass"]}}
    page = _text(report_summary(summary, tmp_path / "rep").index.read_text(encoding="utf-8"))
    assert "897832680500" not in page
    assert "window 13, 1000 samples, 03:56:01.0 to 03:56:03.0 UTC" in page
    assert "from the identify JSON" not in page
    assert "The last speed model (window 13): its fit and correlation tests" in page
    assert "verdict pass" in page
    assert ("speed windows 50/52 passed their cross-validation, 2 failed: consistent with a "
            "correct model, which fails 1 in 20 by chance; p = 0.74") in page
    assert "stable, 1 pole, largest radius" in page and "1 poles" not in page
