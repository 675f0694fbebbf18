"""The real EMPS recording (../shared, closed loop, 1 kHz) against its rigid-mass plant.

The benchmark's IDIM-LS reference (Janot, Gautier, Brunot 2019): M = 95.1089 kg,
Fv = 203.5034 N s/m, Fc = 20.3935 N, offset = -3.1648 N. With M and Fv in plants/emps.yaml,
``diagnose`` must name Coulomb friction and the offset within 5 % and 10 % of those values
and show the fit improve on held-out data. The recording goes through ``import-mat``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import EMPS_MAT, EmpsDiagnosis

from pmsm_sysid.cli import main

FC_REF, OFFSET_REF = 20.3935, -3.1648


@pytest.mark.slow
@pytest.mark.xdist_group("emps")  # the import and its diagnosis: made once (conftest)
def test_emps_names_coulomb_friction_and_offset(shared_dir: Path,
                                                emps_diagnosis: EmpsDiagnosis,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert EMPS_MAT.is_file(), f"{EMPS_MAT} missing"
    bag = emps_diagnosis.bag
    assert emps_diagnosis.imported.returncode == 0, emps_diagnosis.imported.stderr
    # identify reads only as far as its windows need: that is not a truncated bag
    assert main(["identify", str(bag), "--terms", "4", "--ny", "2", "--nu", "2"]) == 0
    assert "warning: reading the bag" not in capsys.readouterr().out
    out, rep = emps_diagnosis.json, emps_diagnosis.report
    assert emps_diagnosis.diagnosed.returncode == 0, emps_diagnosis.diagnosed.stderr
    summary = emps_diagnosis.diagnosed.stdout
    d = json.loads(out.read_text())
    named = {e["name"]: e for e in d["effects"] if e["name"] != "unexplained"}
    coulomb, offset = named["coulomb_friction"], named["force_offset"]
    assert coulomb["params"]["amplitude_n"] == pytest.approx(FC_REF, rel=0.05)
    assert offset["params"]["amplitude_n"] == pytest.approx(OFFSET_REF, rel=0.10)
    for e in (coulomb, offset):
        assert e["held_out"]["confirmed"] and e["significance"] > 10
    others = [e for n, e in named.items() if n not in ("coulomb_friction", "force_offset")]
    assert all(e["explains"] < 0.05 for e in others), others
    assert d["method"]["feedback"]["closed_loop"]  # the rig runs under position control
    assert d["method"]["speed_source"] == "derived from position"
    for seg in ("estimation", "validation"):
        fit = d["fit"][seg]
        assert fit["nrmse_after"] < 0.2 * fit["nrmse_before"], fit
        assert fit["output_error"]["nrmse_after"] < 0.2 * fit["output_error"]["nrmse_before"]
    assert "coulomb_friction" in summary and "force_offset" in summary
    # over frequency: the rig's NARX is significantly nonlinear, the rigid-mass twin's not
    (g,) = [w for w in d["mismatch"]["where"] if w.get("source") == "gfrf"]
    assert g["real"]["significant"] and not g["twin"]["significant"]
    corrected = d["corrected_plant"]
    assert corrected["coulomb_friction"]["amplitude_n"] == pytest.approx(FC_REF, rel=0.05)
    assert corrected["mass_kg"] == pytest.approx(95.1089)
    # the page says what a control engineer reads right: the corrected plant with the
    # effects found (it once showed the nominal plant again), the unexplained force in words
    # and mm (it once dumped 30 curve numbers), no inf, shares that add to at most 100 %
    import html
    import re

    page = (rep / "index.html").read_text(encoding="utf-8")
    text = " ".join(html.unescape(re.sub(r"<[^>]+>", " ", re.sub(
        r"<style.*?</style>", " ", page, flags=re.S))).split())
    corrected_part = text[text.index("Corrected plant the nominal plant with"):]
    assert "coulomb_friction.amplitude_n 20.5" in corrected_part
    assert "force_offset.amplitude_n -3.1" in corrected_part
    assert " inf " not in text and "force_n" not in text
    if any(e["name"] == "unexplained" for e in d["effects"]):
        lines = [part.splitlines()[0] for part in summary.split("unexplained:")[1:]]
        over_position = [e for e in d["effects"] if e["name"] == "unexplained"
                         and e["params"]["axis"] == "position"]
        assert len([ln for ln in lines if " mm" in ln]) == len(over_position), lines
        assert "effect_unexplained" in page  # its curve drawn from the JSON
    where = d["mismatch"]["where"]
    assert sum(w["added_share"] for w in where if "added_share" in w) <= 1.0 + 1e-9
    assert "mismatch lives over: velocity 9" in summary
