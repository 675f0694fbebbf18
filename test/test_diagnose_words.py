"""What a diagnosis says, read as a control engineer reads it: an unexplained force by where
it acts (mm on a linear axis, the end of the stroke named), no raw curve numbers, no ``inf``,
shares of the mismatch that add up to at most 100 %, and the corrected plant's effects on
the page (it once showed the nominal plant again)."""

from __future__ import annotations

import math
import re
from typing import Any

from pmsm_sysid.core.discrepancy.words import significance_text, unexplained_text, where_text
from pmsm_sysid.report.diagnose import corrected_section, effects_table, where_table

# the unexplained entry of the EMPS diagnosis, as its JSON holds it
EMPS_UNEXPLAINED = {
    "axis": "position", "model": "cubic B-spline over position",
    "region": [0.24015, 0.24631], "peak_at": 0.24631, "peak_n": 3.5777, "width": 0.0061535,
    "unit": "m", "curve": {"at": [0.00016452, 0.12324, 0.24631],
                           "force_n": [-2.3413, -4.4138, 0.084232]}}


def test_an_unexplained_force_is_said_where_it_acts_in_mm() -> None:
    text = unexplained_text(EMPS_UNEXPLAINED)
    assert text == ("an extra force of +3.58 N (against the curve's median) at the end of the "
                    "stroke, x = 240.2-246.3 mm (largest at 246.3 mm; a smooth curve over "
                    "position)")
    inside = dict(EMPS_UNEXPLAINED, region=[0.1, 0.11], peak_at=0.105, peak_n=-1.0)
    assert "inside the stroke, x = 100.0-110.0 mm" in unexplained_text(inside)
    assert "-1 N" in unexplained_text(inside)
    friction = dict(inside, model="cubic B-spline over position, friction (force x sign of "
                                  "speed)")
    assert unexplained_text(friction).startswith("a friction force (x sign of speed) of -1 N")
    timed = {"axis": "time", "frequency_hz": 1.5, "amplitude_n": 0.8, "unit": "s"}
    assert unexplained_text(timed) == "a sinusoidal force over time, 1.5 Hz, amplitude 0.8 N"


def test_significance_never_prints_inf_or_minus_zero() -> None:
    assert significance_text(math.inf) == ">300" and significance_text(301.0) == ">300"
    assert significance_text(-0.0) == "0.0" and significance_text(-2.0) == "0.0"
    assert significance_text(None) == "n/a" and significance_text(21.607) == "21.6"


WHERE = [  # the EMPS nominal residual: alone the axes overlap (72 + 7 + 96 > 100 %)
    {"axis": "time", "share": 0.722, "significance": 1.76, "added_share": 0.006},
    {"axis": "position", "share": 0.066, "significance": -0.0, "added_share": 0.001},
    {"axis": "velocity", "share": 0.957, "significance": None, "added_share": 0.957},
    {"axis": "frequency", "share": 5e-5, "significance": 0.17, "added_share": 0.0},
    {"axis": "frequency", "source": "gfrf", "share": None, "significance": 21.6},
]


def test_where_the_mismatch_lives_adds_up_to_at_most_100_percent() -> None:
    assert where_text(WHERE) == "velocity 96 %"  # the others are not significant
    strong = [dict(w, significance=10.0) for w in WHERE[:3]]
    assert where_text(strong) == "velocity 96 %, time +1 %"  # position adds +0.1 %: left out
    table = where_table({"mismatch": {"where": WHERE}})
    assert table.header == ("axis", "adds", "alone", "significance (-log10 p)")
    assert table.rows[0] == ("velocity", "+95.7%", "95.7%", ">300")  # null: p underflowed
    assert table.rows[2] == ("position", "+0.1%", "6.6%", "0.0")
    adds = [float(r[1].strip("+%")) for r in table.rows if r[1] != "n/a"]
    assert sum(adds) <= 100.0
    assert "do not add up" in table.caption and "at most 100 %" in table.caption
    assert not any("inf" in cell for row in table.rows for cell in row)


def _diagnosis() -> dict[str, Any]:
    nominal = {"mass_kg": 95.1089, "viscous_n_per_mps": 203.5034, "sample_rate_hz": 1000.0}
    corrected = {**nominal, "coulomb_friction": {"amplitude_n": 20.507,
                                                 "smoothing_mps": 0.001},
                 "force_offset": {"amplitude_n": -3.1727}}
    effects = [{"name": "coulomb_friction", "params": {"amplitude_n": 20.507},
                "significance": 300.0, "explains": 0.967, "confidence": "high"},
               {"name": "unexplained", "params": EMPS_UNEXPLAINED, "significance": 22.96,
                "explains": 0.025, "confidence": "moderate"}]
    return {"plant": nominal, "corrected_plant": corrected, "effects": effects}


def test_the_corrected_plant_on_the_page_holds_the_effects_found() -> None:
    section = corrected_section(_diagnosis())
    note, facts = section.blocks
    assert note.text.startswith("the nominal plant with coulomb_friction added, force_offset "
                                "added")
    assert "--corrected-plant FILE" in note.text
    rows = dict(facts.items)
    assert rows["coulomb_friction.amplitude_n"] == "20.507 N"
    assert rows["force_offset.amplitude_n"] == "-3.1727 N"
    assert rows["mass_kg"] == "95.109 kg"
    assert list(rows)[:3] == ["coulomb_friction.amplitude_n", "coulomb_friction.smoothing_mps",
                              "force_offset.amplitude_n"]  # what was added comes first
    d = _diagnosis()
    d["corrected_plant"] = dict(d["plant"])
    assert corrected_section(d).blocks[0].text.startswith("no effect added")


def test_the_effects_table_has_words_not_curve_numbers() -> None:
    rows = effects_table(_diagnosis()).rows
    assert rows[0][2] == ">300"
    unexplained = rows[1][1]
    assert unexplained.startswith("an extra force of +3.58 N")
    assert not re.search(r"force_n|curve=|at=|\d;", unexplained)
