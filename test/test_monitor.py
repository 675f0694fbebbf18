"""monitor: rate/gap bookkeeping without ROS, the result view, and the node on a live topic."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from pmsm_sysid.cli.monitor import render
from pmsm_sysid.core.online.monitoring import SysIdView, TopicStats

NS = 1_000_000_000


def test_regular_stream_has_no_gaps_and_its_rates() -> None:
    """500 Hz stamps received at 100 Hz of wall time (a 5x slowed replay)."""
    s = TopicStats("/pmsm/speed")
    for k in range(400):
        s.feed(receive_s=10.0 + k / 100.0, stamp_ns=k * NS // 500, value=float(k))
    assert s.count == 400
    assert s.gaps == 0 and s.missing == 0 and s.backwards == 0
    assert s.stamp_rate_hz() == pytest.approx(500.0, rel=1e-9)
    # the 2 s window holds ~200 receive times 0.01 s apart: (n - 1) / span = 100 Hz
    assert s.rate_hz() == pytest.approx(100.0, rel=1e-9)
    assert s.last_value == 399.0


def test_gaps_count_missing_samples_and_backwards_steps() -> None:
    s = TopicStats("/pmsm/thrust")
    stamps = [k * 2_000_000 for k in range(10)]          # 2 ms period
    stamps += [stamps[-1] + 4 * 2_000_000]               # 3 samples missing
    stamps += [stamps[-1] + 2_000_000 * j for j in range(1, 5)]
    stamps += [stamps[-1] + 2_000_000 * 2]               # 1 missing (step = 2 periods)
    stamps += [stamps[-1] + 2_000_000]
    stamps += [stamps[-1]]                               # repeated stamp
    stamps += [stamps[-1] + 1_000_000]                   # 0.5 period: not a gap
    for i, st in enumerate(stamps):
        s.feed(receive_s=float(i), stamp_ns=st)
    assert s.gaps == 2
    assert s.missing == 4
    assert s.backwards == 1


def test_step_just_below_one_and_a_half_periods_is_not_a_gap() -> None:
    s = TopicStats("/x", expected_period_s=0.002)
    s.feed(0.0, 0)
    s.feed(0.1, 2_999_999)          # 1.4999995 periods
    s.feed(0.2, 2_999_999 + 3_000_001)  # 1.5000005 periods
    assert s.gaps == 1 and s.missing == 1  # round(1.5000005) - 1 = 1


def test_rate_window_forgets_old_messages() -> None:
    s = TopicStats("/x", window_s=1.0)
    for k in range(50):
        s.feed(k / 50.0)  # 50 Hz for 1 s, no stamps
    assert s.rate_hz() == pytest.approx(50.0)
    assert s.rate_hz(now_s=5.0) == 0.0  # all older than the window
    assert s.snapshot(now_s=5.0)["age_s"] == pytest.approx(5.0 - 49 / 50.0)


def test_sysid_view_parses_identify_gfrf_and_diagnostics() -> None:
    v = SysIdView(max_events=2)
    assert "model: none yet" in render(_snap(v), 1.0)
    model = {"input": "thrust", "output": "speed", "sample_rate_hz": 500.0,
             "terms": [{"name": "y(k-1)", "estimate": 0.93, "std": 0.01, "err": 0.9},
                       {"name": "u(k-1)", "estimate": 1e-3, "std": 1e-5, "err": 0.05}],
             "validation": {"validation": {"nmse": 0.01, "r2": 0.99}}}
    v.on_model(json.dumps(model))
    v.on_ridges(json.dumps({"stable": True, "h1": {"peaks": [{"freq_hz": 16.5}]},
                            "h2": {"ridges": [{"kind": "f1+f2", "freq_hz": 33.0}]}}))
    v.on_model(json.dumps(dict(model, output="position")))
    v.on_validation([{"name": "ee", "level": 0, "message": "ok"},
                     {"name": "ue", "level": 0, "message": "ok"}])
    v.on_validation([{"name": "ue", "level": 2, "message": "out of band"}])  # replaces 'ue'
    v.on_validation([{"name": "gfrf", "level": 0, "message": "stable"}])  # another source
    for i in range(3):
        v.on_change(float(i), [{"name": "cogging", "level": 1, "message": f"event {i}"}])
    snap = v.snapshot()
    assert snap["model"]["n_terms"] == 2 and snap["model"]["output"] == "position"
    assert sorted(snap["models"]) == ["position", "speed"]
    assert [t["name"] for t in snap["models"]["speed"]["terms"]] == ["y(k-1)", "u(k-1)"]
    assert snap["ridges"] == {"stable": True, "h1": [16.5], "h2": [33.0], "h3": []}
    assert [(s["name"], s["passed"]) for s in snap["validation"]] == [
        ("ee", True), ("ue", False), ("gfrf", True)]
    assert [c["message"] for c in snap["changes"]] == ["event 1", "event 2"]
    text = render(_snap(v), 1.0)
    assert "y(k-1) 0.93" in text and "FAIL" in text and "out of band" in text
    v.on_model("not json {")
    assert v.snapshot()["model"] == {"error": "not JSON"}


def _snap(v: SysIdView, topics: list[TopicStats] = ()) -> dict:  # type: ignore[assignment]
    return {"namespace": "/pmsm", "topics": [t.snapshot(100.0) for t in topics],
            "sysid": v.snapshot()}


def _corr(passed: bool, max_abs: float) -> str:
    return json.dumps({"max_abs": max_abs, "band": 0.06167304400170015, "pass": passed})


def _busy_view() -> tuple[SysIdView, list[TopicStats]]:
    """What a live run publishes: long JSON texts, full-precision numbers, many ridges."""
    topics = []
    for name, value in (("thrust", -4.079530182), ("speed", -0.2059921), ("position", 7.39e-5)):
        s = TopicStats(f"/pmsm/{name}")
        for k in range(2023):
            s.feed(99.0 + k / 2023, k * 2_000_000, value)
        topics.append(s)
    model = TopicStats("/pmsm_sysid/model")
    text = json.dumps({"input": "thrust", "output": "position", "sample_rate_hz": 500.0,
                       "terms": [{"name": "y(k-1)", "estimate": 0.9982449120238887}]})
    model.feed(99.5, None, text[:48])
    topics.append(model)
    v = SysIdView()
    terms = [{"name": n, "estimate": e, "err": r} for n, e, r in (
        ("y(k-15)", -1.5415123456789012, 0.61), ("u(k-7)", -0.0022396812345678, 0.2),
        ("const", 3.722021234567e-15, 0.001), ("y(k-18)u(k-26)", -3.9021123e-16, 0.0004),
        ("u(k-3)^2", -1.16551e-18, 0.0001), ("y(k-1)y(k-2)", 0.12345678901234567, 0.1))]
    v.on_model(json.dumps({"output": "speed", "terms": terms, "speed_derived": True,
                           "validation": {"validation": {"r2": 0.9982449120238887}}}))
    v.on_ridges(json.dumps({"stable": False, "h1": {"peaks": [{"freq_hz": 16.66687011718}]},
                            "h2": {"ridges": [{"freq_hz": f} for f in
                                              (16.8, 116.60000000000001, 149.9, 249.9, 50.0,
                                               83.3, 183.2)]}}))
    v.on_validation([{"name": "identifier/cross_validation/speed", "level": 1,
                      "message": "fail: free-run NRMSE 1.61e-12, R2 1 on the next window",
                      "values": {"nrmse": "1.6086921969040665e-12", "r2": "0.9982449120238887",
                                 "min_r2": "0.9", "diverged": "false",
                                 "corr.ee": _corr(False, 0.9421243257642296),
                                 "corr.ue": _corr(True, 0.011854537755205102),
                                 "corr.u2e2": _corr(False, 0.14532937487395034),
                                 "change_score": "2.3456789012345", "change_state": "steady",
                                 "change_threshold": "7.0"}},
                     {"name": "gfrf/validation/position", "level": 0, "message": "ok",
                      "values": {"r2": "0.99912345678901234", "corr.ee.max_abs": "0.01",
                                 "corr.ee.band": "0.06", "corr.ee.pass": "true"}},
                     {"name": "identifier/cross_validation/position", "level": 1,
                      "message": "fail", "values": {"r2": "0.41234567890123456",
                                                    "min_r2": "0.9", "diverged": "false"}}])
    for k in range(4):
        v.on_change(1795568864.998 + k, [{
            "name": "identifier/change/speed", "level": 1,
            "message": "plant change on speed: xval_nrmse, fit_nrmse, harmonics_db",
            "values": {"reasons": json.dumps(["xval_nrmse", "fit_nrmse", "harmonics_db"]),
                       "z": json.dumps({"xval_nrmse": 55.96864935708172,
                                        "fit_nrmse": 47.74053331982079,
                                        "harmonics_db": 1.8191951921718033})}}])
    return v, topics


def test_view_fits_80_columns_plainly() -> None:
    """A busy snapshot on an 80-column console: every line fits, no raw JSON, no long
    numbers; units on values; each validation says pass/fail and why; events have a time."""
    v, topics = _busy_view()
    text = render(_snap(v, topics), 12.3, width=80)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 80, max(lines, key=len)
    assert "speed (derived)" in text  # speed derived from position is marked
    assert "{" not in text and '"' not in text  # no raw JSON
    assert not re.search(r"\d{7,}", text), re.search(r"\d{7,}", text)  # no 16-digit numbers
    assert "-4.08 N" in text and "-0.206 m/s" in text and "0.0739 mm" in text
    assert "Hz" in text and "ms" in text
    # the latest model as its top terms by ERR: the largest first, the smallest not shown
    assert text.index("y(k-15) -1.54") < text.index("u(k-7) -0.00224")
    assert "u(k-3)^2" not in text and "+2" in text
    by_test = {" ".join(line.split()[:3]): line for line in lines
               if line.startswith(("speed ", "position "))}
    assert "FAIL" in by_test["speed next window"]
    assert "ee 0.942 > 0.0617" in by_test["speed next window"]
    assert "pass" in by_test["position own window"]
    assert "R² 0.999" in by_test["position own window"]
    assert "free-run R² 0.412 < 0.900" in by_test["position next window"]
    assert "2023 Hz" in text  # a rate of thousands without an exponent
    assert "00:" in text and "next-window NRMSE z=56" in text  # event time and reason
    assert "change score speed 2.35 (threshold 7)" in text
    wide = render(_snap(v, topics), 12.3, width=120)
    assert max(len(line) for line in wide.splitlines()) <= 120


def _speed_status(ee: float, outside: int, r2: str, run: list[int]) -> dict[str, Any]:
    """An identifier's speed validation status as the monitor receives it: the ee test's
    largest correlation (band 0.062, 4 of 20 lags allowed outside) and the run's count."""
    corr = json.dumps({"max_abs": ee, "band": 0.062, "pass": ee <= 0.062, "n_outside": outside,
                       "n_lags": 20, "n_allowed": 4})
    values = {"r2": r2, "min_r2": "0.9", "diverged": "false", "corr.ee": corr,
              "windows_passed": str(run[0]), "windows_validated": str(run[1]),
              "run_consistent": "true"}
    return {"name": "identifier/cross_validation/speed", "level": 0 if ee <= 0.062 else 1,
            "message": f"window {'pass' if ee <= 0.062 else 'fail'}", "values": values}


def test_the_validation_title_is_one_line_above_a_narrow_table() -> None:
    """Passing windows make a narrow table; it is as wide as its title, which stays whole
    on a 100-column terminal (it wrapped mid-phrase)."""
    v = SysIdView()
    v.on_validation([_speed_status(0.05, 0, "0.997", [27, 27])])
    lines = [ln.rstrip() for ln in render(_snap(v), 1.0, width=100).splitlines()]
    assert "validation (run: windows passed; a correct model fails 1 in 20)" in lines, lines


def test_a_failed_window_of_a_run_that_passes_reads_as_chance() -> None:
    """The identifier's status carries the run's windows: a window failing a correlation
    test in a run that fails no more often than a correct model (1 in 20) is 'fail' by
    chance with the run's count beside it, not a red FAIL; in a run that fails too often it
    is FAIL with what to try. Rows say which check they are (next window, own window)."""
    v = SysIdView()
    status = _speed_status(0.116, 5, "0.996", [50, 52])
    values = status["values"]
    v.on_validation([status,
                     {"name": "gfrf/validation/speed", "level": 1, "message": "warn",
                      "values": {"corr.ee.max_abs": "0.116", "corr.ee.band": "0.062",
                                 "corr.ee.pass": "false", "stable": "true"}}])
    text = render(_snap(v), 1.0, width=200)  # one row a line (at 80 columns they wrap)
    assert max(len(ln) for ln in render(_snap(v), 1.0, width=80).splitlines()) <= 80
    lines = {" ".join(ln.split()[:3]): ln for ln in text.splitlines()
             if ln.startswith("speed ")}
    assert lines["speed next window"].split()[3:5] == ["fail", "50/52"]
    assert "ee 0.116 > 0.062, 5/20 lags out (4 ok): by chance" in lines["speed next window"]
    assert lines["speed own window"].split()[3:5] == ["fail", "50/52"]
    assert "FAIL" not in text and "a correct model fails 1 in 20" in text
    values["run_consistent"] = "false"
    values["windows_passed"] = "40"
    v.on_validation([{"name": "identifier/cross_validation/speed", "level": 1,
                      "message": "window fail", "values": values}])
    line = next(ln for ln in render(_snap(v), 1.0, width=200).splitlines()
                if ln.startswith("speed") and "next window" in ln)
    assert line.split()[3:5] == ["FAIL", "40/52"] and "residual not white" in line


def test_nothing_received_says_what_to_check(monkeypatch: pytest.MonkeyPatch) -> None:
    from pmsm_sysid.cli.monitor_view import nothing_received

    monkeypatch.setenv("ROS_DOMAIN_ID", "17")
    snap = _snap(SysIdView(), [TopicStats("/pmsm/thrust")])
    hint = nothing_received(snap)
    assert hint is not None and "nothing received on /pmsm yet" in hint
    assert "ROS_DOMAIN_ID=17" in hint and "pmsm-sysid run" in hint and "--namespace" in hint
    assert hint in render(snap, 3.0, width=200)
    s = TopicStats("/pmsm/thrust")
    s.feed(1.0, 0, 1.0)
    assert nothing_received(_snap(SysIdView(), [s])) is None


@pytest.mark.ros
def test_monitor_node_counts_a_live_stream(ros_context: object) -> None:
    """A publisher with a deliberate 3-sample hole: the node reports count, value and gap."""
    import uuid

    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    from pmsm_sysid.nodes.monitor import MonitorNode
    from pmsm_sysid.rosutil import data_qos, make_sample_messages, message_class
    from pmsm_sysid.topics import SPEED_TYPE

    ns = f"/t{uuid.uuid4().hex[:10]}"  # a namespace of its own: no cross-talk between runs
    mon = MonitorNode(context=ros_context, namespace=ns)  # type: ignore[arg-type]
    from rclpy.node import Node

    pub_node = Node("pub", context=ros_context)  # type: ignore[arg-type]
    pub = pub_node.create_publisher(message_class(SPEED_TYPE), f"{ns}/speed", data_qos())
    model_pub = pub_node.create_publisher(String, f"{ns}/model", 10)
    ex = SingleThreadedExecutor(context=ros_context)  # type: ignore[arg-type]
    ex.add_node(mon)
    ex.add_node(pub_node)
    try:
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() < 1 or model_pub.get_subscription_count() < 1:
            assert time.monotonic() < deadline, "monitor did not match"
            ex.spin_once(timeout_sec=0.05)
        ks = [k for k in range(60) if not 20 <= k < 23]
        for k in ks:
            pub.publish(make_sample_messages(k * 2_000_000, 0.0, 0.01 * k, 0.0)["speed"])
        model_pub.publish(String(data=json.dumps({"output": "speed", "terms": [
            {"name": "y(k-1)", "estimate": 0.5}]})))
        stats = mon.stats[f"{ns}/speed"]
        while stats.count < len(ks) or mon.view.model is None:
            assert time.monotonic() < deadline, f"received {stats.count} of {len(ks)}"
            ex.spin_once(timeout_sec=0.05)
        snap = mon.snapshot()
        speed = next(t for t in snap["topics"] if t["topic"] == f"{ns}/speed")
        assert speed["count"] == 57 and speed["gaps"] == 1 and speed["missing"] == 3
        assert speed["last_value"] == pytest.approx(0.59)
        assert speed["stamp_rate_hz"] == pytest.approx(500.0)
        assert snap["sysid"]["model"]["terms"][0]["name"] == "y(k-1)"
    finally:
        ex.shutdown()
        mon.destroy_node()
        pub_node.destroy_node()


@pytest.mark.ros
def test_monitor_cli_once_writes_json(ros_env: int, tmp_path: Path) -> None:
    """With nothing publishing, --once still exits 0 and writes an empty snapshot (to a
    file, and to stdout: the two processes run side by side, both only listen)."""
    out = tmp_path / "snap.json"
    monitor = [sys.executable, "-m", "pmsm_sysid.cli", "monitor", "--once", "--duration", "0.5",
               "--namespace", "/quiet", "--json"]
    procs = [subprocess.Popen([*monitor, target], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for target in (str(out), "-")]
    try:
        done = [(p, *p.communicate(timeout=60)) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    proc, second = (subprocess.CompletedProcess(p.args, p.returncode, o, e) for p, o, e in done)
    assert proc.returncode == 0, proc.stderr
    snap = json.loads(out.read_text())
    assert len(snap["topics"]) == 9 and snap["namespace"] == "/quiet"  # 3 in, 6 out
    assert [t["count"] for t in snap["topics"][:3]] == [0] * 3
    assert "thrust" in proc.stdout and "model: none yet" in proc.stdout
    assert max(len(line) for line in proc.stdout.splitlines()) <= 80  # piped: 80 columns
    assert "\x1b[" not in proc.stdout  # piped: plain text, no colours or cursor moves
    # ... and says what to check (it showed zeros without a hint)
    text = " ".join(proc.stdout.split())
    assert "nothing received on /quiet yet: is a pipeline publishing there with " \
           f"ROS_DOMAIN_ID={ros_env}?" in text
    proc = second
    assert proc.returncode == 0 and json.loads(proc.stdout)["namespace"] == "/quiet"
    assert proc.stderr.startswith("pmsm-sysid monitor: nothing received on /quiet yet")


def test_monitor_cli_bad_interval_is_one_line(ros_env: int,
                                              capfd: pytest.CaptureFixture[str]) -> None:
    """Refused before any work: in this process (reliability_helpers.ros_verb)."""
    from reliability_helpers import ros_verb

    proc = ros_verb(capfd, "monitor", "--interval", "0")
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "--interval" in proc.stderr
