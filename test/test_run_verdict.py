"""The verdict and one-line summary of ``pmsm-sysid run`` name what failed."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from pmsm_sysid.cli.run_verdict import headline, verdict


def _tests(failed: tuple[str, ...] = ()) -> dict[str, Any]:
    return {k: {"pass": k not in failed, "max_abs": 0.05, "band": 0.062}
            for k in ("ee", "ue", "u2e", "u2e2", "e_eu")}


def _validation(output: str, r2: float = 0.996, failed: tuple[str, ...] = (),
                diverged: bool = False) -> dict[str, Any]:
    ok = not failed and not diverged and r2 >= 0.9
    return {"output": output, "pass": ok, "min_r2": 0.9, "correlation_tests": _tests(failed),
            "free_run": {"r2": r2, "nrmse": (1 - r2) ** 0.5, "diverged": diverged}}


def _summary() -> dict[str, Any]:
    models = {o: {"output": o, "terms": [{}] * 16, "data_check": {"warnings": [],
                                                                  "pe_order": 40,
                                                                  "pe_required": 40}}
              for o in ("speed", "position")}
    return {"samples_published": 15000, "samples_received": 15000, "samples_dropped": 0,
            "samples_missing": 0, "windows_fitted": 56, "windows_skipped": 0,
            "last_models": models, "last_model": models["speed"], "last_ridges": None,
            "last_validations": {o: _validation(o) for o in ("speed", "position")},
            "validation_counts": {"speed": [50, 52], "position": [49, 52]},
            "change_events": [], "errors": []}


def test_a_passing_run_says_pass_with_its_figures() -> None:
    s = _summary()
    assert verdict(s)["status"] == "pass"
    line = headline(s)
    assert line.startswith("pass: speed validation pass (free-run R2 0.9960, correlation "
                           "tests 5/5, 50/52 windows passed); position validation pass")
    assert "windows fitted 56, skipped 0" in line and line.endswith("0 change event(s)")


def test_a_failure_names_the_output_and_the_test() -> None:
    s = _summary()
    s["last_validations"]["position"] = _validation("position", failed=("ee", "u2e"))
    s["validation_counts"]["position"] = [40, 52]  # 12 failures: p = 3e-4 at a 1 in 20 rate
    line = headline(s)
    assert line.startswith("FAIL: position validation FAIL: 12 of 52 windows failed, more "
                           "than the 1 in 20 a correct model fails by chance (p = "
                           "0.00033 < 0.01); the latest window: correlation tests ee, u2e "
                           "failed on its estimation window (free-run R2 0.9960, 40/52 "
                           "windows passed)"), line
    assert "speed validation pass" in line  # the output that passed is still reported
    s["last_validations"]["speed"] = _validation("speed", r2=0.85)
    assert "speed validation FAIL: free-run R2 0.8500 < 0.9 on the next window" in headline(s)
    s["last_validations"]["speed"] = _validation("speed", diverged=True)
    assert "speed validation FAIL: free run diverged on the next window" in headline(s)


def test_the_run_is_judged_by_its_windows_not_by_the_latest() -> None:
    """The correlation tests reject a correct model in about 1 window in 20: a latest window
    failing one test while the run's failures stay consistent with that rate at 1 % is a
    pass that names the latest failure as a detail. The windows overlap (a hop of 250 in
    1000 samples), so the count of 52 is judged as 52 / phi windows (phi = 1.56): 8 failures
    of 52 are a pass, 9 are not; with windows far apart the binomial tail itself (8
    failures: P(X >= 8) = 0.0041). A latest free run below min_r2 is never chance."""
    from scipy.stats import beta, binom

    s = _summary()
    s["last_validations"]["position"] = _validation("position", failed=("u2e2",))
    s["validation_counts"]["position"] = [46, 52]
    v = verdict(s)
    assert v["status"] == "pass" and not v["failures"] and not v["warnings"]
    assert v["outputs"][1] == ("position validation pass (free-run R2 0.9960, 46/52 windows "
                               "passed: as often as a correct model, which fails 1 window in "
                               "20 by chance; the latest window: correlation test u2e2 failed "
                               "on its estimation window)")
    assert headline(s).startswith("pass: speed validation pass")
    # scipy.stats (Boost) as the independent truth of the tail used here
    phi = v["windows"]["position"]["dispersion"]
    assert phi == pytest.approx(1.561, abs=1e-3)
    assert v["windows"]["position"]["p_value"] == pytest.approx(
        beta.cdf(0.05, 6 / phi, (52 - 6) / phi + 1), rel=1e-12)
    s["validation_counts"]["position"] = [44, 52]
    assert verdict(s)["status"] == "pass"
    s["validation_counts"]["position"] = [43, 52]
    assert verdict(s)["status"] == "FAIL"
    s["validation_counts"]["position"] = [44, 52]
    s["window_grid"] = {"window": 1000, "hop": 2000}  # windows far apart: independent
    assert binom.sf(7, 52, 0.05) < 0.01 < binom.sf(6, 52, 0.05)
    assert verdict(s)["status"] == "FAIL"
    assert verdict(s)["windows"]["position"]["p_value"] == pytest.approx(binom.sf(7, 52, 0.05),
                                                                         rel=1e-12)
    # the latest window passed, but the run's windows failed too often: still FAIL
    s["last_validations"]["position"] = _validation("position")
    assert verdict(s)["status"] == "FAIL"
    s["validation_counts"]["position"] = [50, 52]
    s["last_validations"]["position"] = _validation("position", r2=0.8)
    assert verdict(s)["status"] == "FAIL"


def test_a_small_hop_needs_more_failed_windows_than_the_default() -> None:
    """With a hop of 50 (windows sharing 95 % of their samples, 81 windows in 5 s of data)
    failures come in long runs: 12 of 81 is a pass there, a FAIL at the default hop."""
    s = _summary()
    s["validation_counts"]["position"] = [69, 81]
    assert verdict(s)["status"] == "FAIL"
    s["window_grid"] = {"window": 1000, "hop": 50}
    v = verdict(s)
    assert v["status"] == "pass" and v["windows"]["position"]["dispersion"] > 4
    s["validation_counts"]["position"] = [41, 81]  # half of them: wrong whatever the hop
    assert verdict(s)["status"] == "FAIL"


def test_one_failed_window_of_one_is_too_few_to_judge() -> None:
    s = _summary()
    s["last_validations"]["position"] = _validation("position", failed=("ee",))
    s["validation_counts"]["position"] = [0, 1]
    v = verdict(s)
    assert v["status"] == "warning"
    assert v["warnings"] == ["position validation: 0/1 windows passed, too few windows to "
                             "judge the run; the latest window: correlation test ee failed "
                             "on its estimation window (free-run R2 0.9960)"]
    s["validation_counts"]["position"] = [0, 2]  # both failed: P = 0.0025
    assert verdict(s)["status"] == "FAIL"


def test_fit_errors_warnings_and_changes_are_named() -> None:
    s = _summary()
    s["errors"] = ["position/12: InsufficientExcitationError: thrust is constant"]
    v = verdict(s)
    assert v["status"] == "FAIL" and "position/12" in v["failures"][0]
    s = _summary()
    s["last_models"]["speed"]["data_check"] = {
        "warnings": ["insufficient excitation: thrust is persistently exciting of order 2"],
        "pe_order": 2, "pe_required": 40}
    s["windows_skipped"] = 9
    s["change_events"] = [{"output": "speed", "window": {"end_stamp": 8.5},
                           "reasons": ["h1_gain_db", "xval_nrmse"]}]
    line = headline(s)
    assert line.startswith("warning: speed data check: insufficient excitation (persistently "
                           "exciting of order 2 < 40 input lags); 1 change event(s): speed at "
                           "8.50 s (h1_gain_db, xval_nrmse); 9 windows skipped; speed "
                           "validation pass")


def test_wall_clock_stamps_read_as_a_time_of_day() -> None:
    """A wall-clock run's stamps count from 1970: a change event at one reads as its UTC
    time of day, not as 1795787670.04 s; a simulated clock's as seconds."""
    s = _summary()
    s["change_events"] = [{"output": "speed", "window": {"end_stamp": 1795787670.04},
                           "reasons": ["h1_gain_db"]}]
    assert "1 change event(s): speed at 13:54:30.0 UTC (h1_gain_db)" in headline(s)
    s["change_events"][0]["window"]["end_stamp"] = 8.5
    assert "1 change event(s): speed at 8.50 s (h1_gain_db)" in headline(s)


def test_no_identifier_here_has_no_verdict_and_no_model_yet_is_a_warning() -> None:
    s = _summary()
    s.update(last_models={}, last_model=None, last_validations={}, samples_received=None)
    assert verdict(s)["status"] == "none"
    assert headline(s).startswith("published 15000 samples")
    s2 = copy.deepcopy(s)
    s2["samples_received"] = 100
    assert headline(s2).startswith("warning: no model fitted yet")
