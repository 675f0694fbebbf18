"""'high' confidence is earned on data the effect was not fitted on, for a shape the data
can tell apart: the held-out recording must improve (equation error, significantly; the
replay not worse), and a position-periodic force must repeat over the travel.

Recordings from the battery's independent simulator (bench/battery_plant.py).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from battery_plant import Case, Truth, record

from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.discrepancy.diagnose import cap_on_replay
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.plantfit.fit import confidence as _confidence
from pmsm_sysid.core.plantfit.found import FoundEffect
from pmsm_sysid.core.plantfit.stats import HeldOutTest

FAST = DiagnoseOptions(replay=False, gfrf=False)


def _found(name: str, confidence: str) -> FoundEffect:
    return FoundEffect(name, {}, {}, 50.0, 0.5, HeldOutTest(0.5, 8.0, 1e-15), confidence)


def test_high_needs_a_significant_held_out_improvement() -> None:
    overwhelming = 200.0
    assert _confidence(overwhelming, HeldOutTest(0.4, 6.0, 1e-9), None, 1e-3) == "high"
    assert _confidence(overwhelming, None, None, 1e-3) != "high"
    assert _confidence(overwhelming, HeldOutTest(0.05, 2.0, 0.02), None, 1e-3) == "moderate"
    assert _confidence(overwhelming, HeldOutTest(0.01, 0.5, 0.3), None, 1e-3) == "low"
    assert _confidence(overwhelming, HeldOutTest(0.4, 6.0, 1e-9), None, 1e-3,
                       identified=False) == "moderate"


def test_an_effect_absent_from_the_held_out_recording_is_not_reported() -> None:
    """An offset in the estimation recording only: overwhelming there, but it makes the
    held-out recording (the nominal plant) worse, so it is dropped, with a note."""
    est = record(Case("offset", Truth(offset=1.5), "open", "chirp", "low", 1), 1)
    val = record(Case("nominal", Truth(), "open", "chirp", "low", 1), 101)
    result = diagnose(nominal_plant(), est, val, FAST)
    assert not [e for e in result.effects if e.confidence == "high"]
    assert "force_offset" not in [e.name for e in result.effects]
    assert any("not confirmed on held-out data" in n for n in result.notes)


def test_a_worse_held_out_replay_takes_high_away() -> None:
    found = [_found("cogging", "high"), _found("force_offset", "moderate")]
    worse: dict[str, Any] = {"validation": {"output_error": {"verdict": "worse"}}}
    capped, notes = cap_on_replay(found, worse)
    assert [e.confidence for e in capped] == ["moderate", "moderate"]
    assert notes and "cogging" in notes[0]
    for verdict in ("better", "unresolved", "same"):
        kept, none = cap_on_replay(found, {"validation": {"output_error": {"verdict": verdict}}})
        assert [e.confidence for e in kept] == ["high", "moderate"] and not none
    assert cap_on_replay(found, {"validation": {}})[0] == found  # --no-replay


def test_a_pitch_as_long_as_the_travel_is_not_high_cogging() -> None:
    """A local bump under a position loop: a 41 mm 'cogging' with harmonics over a 47 mm
    travel (and an offset) fits it, but no phase of it is met twice -- it is a curve over
    position, so no library name stays 'high' and the curve says where the force is."""
    case = Case("bump", Truth(bump=(0.5, 0.010, 0.003)), "closed", "chirp", "low", 1)
    result = diagnose(nominal_plant(), record(case, 1), record(case, 101), FAST)
    cog = [e for e in result.effects if e.name == "cogging"]
    assert cog and cog[0].confidence != "high"
    assert any("not identified as periodic" in n for n in cog[0].notes)
    assert not [e for e in result.effects if e.name != "unexplained" and e.confidence == "high"]
    un = [e for e in result.effects if e.name == "unexplained"]
    assert un and un[0].params["axis"] == "position"
    lo, hi = un[0].params["region"]
    # around the bump's centre (10 mm), within two of its widths (sigma 3 mm) on each side
    assert 0.004 < lo < 0.010 < hi < 0.016, (lo, hi)


def test_a_pitch_met_many_times_over_the_travel_stays_high() -> None:
    """The control: 0.6 N of cogging at 7 mm under the same loop (about 7 periods)."""
    case = Case("cogging", Truth(cogging=(0.6, 0.007, 1.1)), "closed", "aprbs", "high", 1)
    result = diagnose(nominal_plant(), record(case, 1), record(case, 101), FAST)
    (cog,) = [e for e in result.effects if e.name == "cogging"]
    assert cog.confidence == "high"
    assert cog.params["pitch_m"] == pytest.approx(0.007, rel=0.03)

