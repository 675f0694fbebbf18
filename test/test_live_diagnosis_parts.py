"""The parts of the live diagnosis that need no executor: spans in seconds on a stream whose
rate comes from its stamps, the simulator's latest span, the words and numbers read from a
diagnosis, the span-by-span history, the monitor's line, the node's health and the run
report's figure."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest

from pmsm_sysid import diagnosed
from pmsm_sysid.core.online.spans import LatestSpan, SpanSizer, samples_of


def _diagnosis(effects: list[dict[str, Any]], end: float = 120.0, run: int = 12,
               skipped: int = 0) -> dict[str, Any]:
    return {"effects": effects, "window": {"seq": int(end / 10), "end_stamp": end - 0.002,
                                           "samples": 15000, "sample_rate_hz": 500.0},
            "fit": {"validation": {"nrmse_before": 0.18, "nrmse_after": 0.06}},
            "counts": {"diagnoses_run": run, "diagnoses_skipped": skipped},
            "reference": "plant_file"}


COULOMB = {"name": "coulomb_friction", "params": {"amplitude_n": 2.0123},
           "confidence": "high"}
COGGING = {"name": "cogging", "params": {"amplitude_n": 1.004, "pitch_m": 0.0049998,
                                         "phase_rad": 0.52, "harmonics": []},
           "confidence": "moderate"}
LOCAL = {"name": "unexplained", "params": {"axis": "position", "region": [0.01, 0.02]},
         "confidence": "low"}


def test_spans_in_seconds_follow_the_rate_the_stamps_tell() -> None:
    calls: list[tuple[int, int]] = []
    sizer = SpanSizer(30.0, 10.0, 500.0, lambda a, b: calls.append((a, b)))
    assert sizer.sizes == (15000, 5000) and calls == []
    sizer.check(None)  # rate not known yet: nothing changes
    sizer.check(2_000_000)  # 500 Hz, as provisioned
    assert calls == []
    sizer.check(1_000_000)  # the stamps say 1 kHz
    assert calls == [(30000, 10000)] and sizer.sizes == (30000, 10000)
    sizer.set_seconds(20.0, 5.0)
    assert calls[-1] == (20000, 5000)
    assert samples_of(0.0021, 1_000_000) == 2  # at least two samples
    with pytest.raises(Exception, match="positive"):
        samples_of(-1.0, 1_000_000)


def test_the_simulators_latest_span_is_cut_every_period_and_derives_a_missing_speed() -> None:
    span = LatestSpan(1000, 500)  # 1 s every 0.5 s at 1 kHz
    for k in range(2600):  # thrust and position only: speed derived from position
        stamp = 5_000_000_000 + k * 1_000_000
        span.push("thrust", stamp, math.sin(k / 50))
        span.push("position", stamp, 1e-3 * k)
    w = span.latest
    assert w is not None and span.sample_rate_hz == pytest.approx(1000.0)
    assert w.speed_derived and w.stop_index - w.start_index == 1000
    assert (w.stop_index) % 500 == 0 and w.end_stamp <= 5.0 + 2.599
    rec = w.recording(1000.0, with_history=False)
    assert rec.speed_derived and rec.speed == pytest.approx(1.0)  # 1 mm per ms
    assert rec.thrust[-1] == pytest.approx(math.sin((w.stop_index - 1 - 5000) / 50))


def test_numbers_of_a_diagnosis_are_nan_for_what_it_did_not_name() -> None:
    n = diagnosed.numbers(_diagnosis([COULOMB, LOCAL]))
    assert n["coulomb_friction/amplitude_n"] == 2.0123
    assert math.isnan(n["cogging/amplitude_n"]) and math.isnan(n["thrust_lag/tau_s"])
    assert (n["effects_named"], n["unexplained"]) == (1.0, 1.0)
    assert (n["force_nrmse_before"], n["force_nrmse_after"]) == (0.18, 0.06)
    assert set(n) == set(diagnosed.numbers({}))  # the same quantities for every diagnosis
    assert all(math.isnan(v) for k, v in diagnosed.numbers({}).items()
               if k not in ("effects_named", "unexplained"))


def test_what_a_diagnosis_found_in_words() -> None:
    assert diagnosed.effect_text(COULOMB) == "coulomb_friction 2.01 N (high)"
    assert diagnosed.effect_text(COGGING) == "cogging 1 N at 5 mm (moderate)"
    assert diagnosed.effect_text(LOCAL, confidence=False) == "unexplained (position)"
    assert diagnosed.found_text(_diagnosis([])) == "nothing missing"
    assert diagnosed.found_text(_diagnosis([COULOMB, COGGING, LOCAL]), limit=1) == \
        "coulomb_friction 2.01 N (high) +2"
    line = diagnosed.line(_diagnosis([COULOMB]))
    assert line == ("diagnosis of 30 s ending at t=120.0 s: coulomb_friction 2.01 N (high); "
                    "held-out force NRMSE 0.18 -> 0.06")


def test_the_history_keeps_the_whole_run_in_bounded_rows() -> None:
    h = diagnosed.DiagnosisHistory(max_rows=8)
    for i in range(40):
        h.add(_diagnosis([COULOMB] if i >= 20 else [], end=30.0 + 10 * i))
    d = h.to_dict()
    assert d["diagnoses"] == 40 and len(d["rows"]) <= 8 and d["stride"] == 8
    ts = [r["t"] for r in d["rows"]]
    assert ts == sorted(ts) and ts[0] == pytest.approx(29.998) and ts[-1] > 300.0
    assert [r["effects"] for r in d["rows"]] == [[]] * 3 + [["coulomb_friction"]] * 2
    assert d["rows"][-1]["numbers"]["coulomb_friction/amplitude_n"] == 2.0123
    assert "cogging/amplitude_n" not in d["rows"][-1]["numbers"]  # NaN is left out


def test_the_monitor_shows_the_diagnosis_in_one_line_of_80_columns() -> None:
    from pmsm_sysid.cli.monitor_view import diagnosis_line
    from pmsm_sysid.core.online.monitoring import SysIdView

    view = SysIdView()
    assert diagnosis_line(view.snapshot()).plain == "diagnosis: none yet"
    import json

    for effects in ([], [COULOMB], [COULOMB, COGGING, LOCAL, COULOMB | {"name": "spring"}]):
        view.on_diagnosis(json.dumps(_diagnosis(effects)))
        line = diagnosis_line(view.snapshot()).plain
        assert len(line) <= 80 and "\n" not in line, line
        assert line.startswith("diagnosis t=120.0 s, 12 run/0 skipped: ")
    assert line.endswith("...")
    view.on_diagnosis(json.dumps(_diagnosis([COULOMB])))
    assert diagnosis_line(view.snapshot()).plain.endswith("coulomb_friction 2.01 N (high)")
    view.on_diagnosis("not json")
    assert diagnosis_line(view.snapshot()).plain == "diagnosis: unreadable message"


def _node(last: dict[str, Any] | None, **kw: Any) -> Any:
    counts = {"diagnoses_due": 3, "diagnoses_run": 3, "diagnoses_skipped": 0,
              "diagnoses_failed": 0, **kw.pop("counts", {})}
    stats = SimpleNamespace(samples_received=kw.pop("received", 45000),
                            fit_latency_p50_ms=3000.0, fit_latency_p99_ms=4000.0)
    return SimpleNamespace(counts=lambda: counts, last=last, engine=SimpleNamespace(stats=stats),
                           sample_rate_hz=lambda: 500.0, params={"span_s": 30.0},
                           plant=object(), reference="plants/nominal.yaml",
                           last_failed=kw.pop("failed", None),
                           skips_before_last=kw.pop("skips_before", 0))


@pytest.mark.ros
def test_the_health_warns_while_physics_is_missing_and_when_spans_are_lost() -> None:
    from pmsm_sysid.nodes.health import OK, WARN, diagnose_health

    level, message, values = diagnose_health(_node(_diagnosis([])))()
    assert level == OK and message == ("ok: nothing missing from the plant in the latest "
                                       "span; 3 diagnoses run")
    level, message, values = diagnose_health(_node(_diagnosis([COULOMB])))()
    assert level == WARN and message == "missing from the plant: coulomb_friction 2.01 N (high)"
    assert values["effects"] == "coulomb_friction" and values["force_nrmse_after"] == 0.06
    level, message, _ = diagnose_health(_node(None, received=5000))()
    assert level == OK and message == "ok: collecting the first span (10 of 30 s)"
    level, message, _ = diagnose_health(_node(_diagnosis([]), counts={"diagnoses_skipped": 2},
                                              skips_before=1, failed="span ending ...: x"))()
    assert level == WARN and message == ("last diagnosis failed: span ending ...: x; 1 span(s) "
                                         "skipped (diagnoses slower than period_s)")


@pytest.mark.slow
def test_the_run_report_draws_each_effect_over_time(tmp_path: Any) -> None:
    from pmsm_sysid.report.build import kind_of, report_summary

    h = diagnosed.DiagnosisHistory()
    for i in range(6):
        h.add(_diagnosis([COULOMB | {"params": {"amplitude_n": 1.5 + 0.1 * i}}] if i >= 3
                         else [], end=30.0 + 10 * i))
    summary = {"nodes": ["sim", "diagnose"], "clock": "sim", "samples_published": 40000,
               "samples_received": None, "last_model": None, "last_ridges": None,
               "change_events": [], "diagnoses_run": 6, "diagnoses_skipped": 0,
               "diagnoses_failed": 0, "last_diagnosis": _diagnosis([COULOMB]),
               "history": {"outputs": {}, "stride": {}, "events": [],
                           "change_threshold": None, "diagnosis": h.to_dict()}}
    assert kind_of(summary) == "run"
    res = report_summary(summary, tmp_path / "rep")
    assert "run_diagnosis.png" in {p.name for p in res.figures}
    drawn = res.data["run_diagnosis"]
    amp = drawn["effects"]["coulomb_friction/amplitude_n"]
    assert amp["t"] == pytest.approx([0, 10, 20, 30, 40, 50])
    assert all(math.isnan(v) for v in amp["v"][:3])
    assert amp["v"][3:] == pytest.approx([1.8, 1.9, 2.0])
    assert drawn["nrmse"]["force_nrmse_before"]["v"] == pytest.approx([0.18] * 6)
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "Live run: diagnosis over time" in page and "Spans that named missing physics: 3 of 6" \
        in page
