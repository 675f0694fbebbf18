"""Physics outside the library: said to be there, where it lives, modelled by a curve.

Recordings from the battery's independent simulator (bench/battery_plant.py), which has
forces the library does not: an actuator dead zone, a slow time-periodic disturbance,
friction over part of the stroke. Each must come out as ``unexplained`` on the right axis
and region, with a curve that lowers the held-out error, and no library name at 'high'.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from battery_plant import Case, Truth, record

from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.physics.plant import nominal_plant

FAST = DiagnoseOptions(replay=False, gfrf=False)


def _run(case: Case) -> Any:
    return diagnose(nominal_plant(), record(case, 1), record(case, 101), FAST)


def _unexplained(result: Any, *axes: str) -> Any:
    hits = [e for e in result.effects if e.name == "unexplained" and e.params["axis"] in axes]
    assert hits, [(e.name, e.params.get("axis")) for e in result.effects]
    return hits[0]


def _no_library_high(result: Any) -> None:
    assert not [e.name for e in result.effects
                if e.name != "unexplained" and e.confidence == "high"]


def test_actuator_dead_zone_is_unexplained_over_thrust() -> None:
    result = _run(Case("dead_zone", Truth(dead_zone=1.5), "open", "aprbs", "low", 1))
    e = _unexplained(result, "thrust")
    lo, hi = e.params["region"]
    assert lo < 0.5 and hi > -0.5 and hi - lo < 6.0  # the turn of the curve, at 0 N
    assert e.held_out is not None and e.held_out.significant
    _no_library_high(result)


def test_actuator_dead_zone_under_a_position_loop_is_a_bend_over_thrust() -> None:
    """Under feedback the thrust answers the sensor noise, so the residual leans on it in a
    straight line whatever the plant; the dead zone is the bend beyond that line."""
    result = _run(Case("dead_zone", Truth(dead_zone=1.5), "closed", "prbs", "high", 1))
    e = _unexplained(result, "thrust")
    lo, hi = e.params["region"]
    assert lo < 0.5 and hi > -0.5 and hi - lo < 6.0
    assert e.held_out is not None and e.held_out.significant
    _no_library_high(result)


@pytest.mark.parametrize(("exc", "noise"), [("aprbs", "low"), ("prbs", "high")])
def test_a_loop_answering_a_process_force_is_no_bend_over_thrust(exc: str,
                                                                  noise: str) -> None:
    """4 N of white process force under the loop: the residual leans on the thrust (a
    curve over thrust alone predicted held-out data 10 % better), but bends nowhere."""
    result = _run(Case("process_noise", Truth(process=4.0), "closed", exc, noise, 1))
    assert result.effects == ()


@pytest.mark.parametrize("seed", [1, 2])
def test_a_small_local_force_under_high_noise_is_found_where_it_acts(seed: int) -> None:
    """0.5 N over a few millimetres, in 2.5 N of residual noise: 0.6 % of the mismatch,
    lost in the 17 coefficients of a spline but not in one scanned bump."""
    case = Case("bump", Truth(bump=(0.5, 0.010, 0.003)), "open", "multisine", "high", seed)
    result = diagnose(nominal_plant(), record(case, seed), record(case, seed + 100), FAST)
    e = _unexplained(result, "position")
    lo, hi = e.params["region"]
    assert lo < 0.013 and hi > 0.007 and hi - lo < 0.02
    assert e.params["peak_n"] == pytest.approx(0.5, rel=0.35)
    assert e.held_out is not None and e.held_out.significant
    _no_library_high(result)


def test_slow_periodic_disturbance_is_unexplained_over_time() -> None:
    result = _run(Case("periodic", Truth(periodic=(1.0, 0.25)), "open", "prbs", "low", 1))
    e = _unexplained(result, "time", "frequency")  # a slow line: either axis sees it
    assert e.params["frequency_hz"] == pytest.approx(0.25, abs=0.05)
    assert e.params["amplitude_n"] == pytest.approx(1.0, rel=0.3)
    assert e.held_out is not None and e.held_out.significant
    fit = result.fit["validation"]
    assert fit["nrmse_after"] < 0.8 * fit["nrmse_before"]
    _no_library_high(result)


@pytest.mark.parametrize(("loop", "exc", "noise"), [("closed", "multisine", "low"),
                                                     ("open", "chirp", "high")])
def test_friction_over_part_of_the_stroke_lives_over_position(loop: str, exc: str,
                                                              noise: str) -> None:
    """A Coulomb term takes the mean friction; a friction curve over position predicts the
    held-out data better, so the friction is not 'high' and the curve says where it is."""
    case = Case("zone", Truth(zone=(1.5, 0.0, 0.015)), loop, exc, noise, 1)
    result = _run(case)
    e = _unexplained(result, "position")
    lo, hi = e.params["region"]
    # the zone (0 to 15 mm of a 47 mm or longer travel) to within 3 mm at each end
    assert -0.003 <= lo <= 0.003 and 0.012 <= hi <= 0.018, (lo, hi)
    assert e.held_out is not None and e.held_out.significant
    _no_library_high(result)


@pytest.mark.slow
def test_nothing_wrong_gives_no_curve() -> None:
    for loop, exc in (("open", "aprbs"), ("closed", "multisine"), ("open", "multisine")):
        result = _run(Case("nominal", Truth(), loop, exc, "high", 1))
        assert result.effects == (), loop
