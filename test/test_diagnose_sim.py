"""``diagnose --sim SIM_BAG --real BAG``: the user's simulator, known only by a recording,
against the real drive.

Known truths: the "simulator" is a plant that is not the nominal one (3.1 kg, 25 N s/m)
recorded at 1 kHz with a chirp, open loop; the "real" drives are recorded at 500 Hz under a
PID position loop with an excitation injected into the controller's output, with concealed
effects (Coulomb friction, cogging, 6 % more mass), or with the same physics as the
simulator (controls), or without the effects the simulator has (sim-only). Noise on every
signal: speed, position (1 µm encoder), process force, and the thrust reading.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import pytest
from plant_cases import NOISE, SIM_MASS, closed_loop, open_loop, plant

import pmsm_sysid as ps
from pmsm_sysid.bagio import write_joint_states, write_recording
from pmsm_sysid.cli import main
from pmsm_sysid.core.discrepancy import DiagnoseOptions
from pmsm_sysid.core.discrepancy.against import diagnose_sim
from pmsm_sysid.core.physics.plant import Cogging, CoulombFriction, load_plant

FAST = DiagnoseOptions(replay=False, gfrf=False)
REAL_MASS = 1.065 * SIM_MASS
COGGING = Cogging(0.8, 0.006, 0.3)


def _sim():  # type: ignore[no-untyped-def]
    return open_loop(plant(), "chirp", 5.0, 1)


def _real_with_effects(seed: int = 3):  # type: ignore[no-untyped-def]
    truth = plant(500.0, mass_kg=REAL_MASS, coulomb_friction=CoulombFriction(2.0),
                  cogging=COGGING)
    return closed_loop(truth, 5.0, seed, inject="chirp", amplitude=20.0)


@pytest.mark.slow
def test_the_real_axis_is_heavier_and_has_friction_and_cogging_the_simulation_lacks() -> None:
    d = diagnose_sim(_sim(), _real_with_effects(), None, FAST)
    js = d.to_dict()
    assert js["reference"] == "sim_recording"
    rows = {c["parameter"]: c for c in js["changes"]}
    assert set(rows) == {"mass_kg", "coulomb_friction.amplitude_n", "cogging.amplitude_n"}
    assert rows["mass_kg"]["sim"] == pytest.approx(SIM_MASS, rel=0.01)
    assert rows["mass_kg"]["real"] == pytest.approx(REAL_MASS, rel=0.02)
    assert rows["coulomb_friction.amplitude_n"]["sim"] is None
    assert rows["coulomb_friction.amplitude_n"]["real"] == pytest.approx(2.0, rel=0.05)
    assert rows["cogging.amplitude_n"]["real"] == pytest.approx(0.8, rel=0.10)
    assert all(r["confidence"] in ("high", "moderate") for r in rows.values())
    assert {e["name"] for e in js["effects"]} == {"mass_error", "coulomb_friction", "cogging"}
    assert js["sim_only"] == []
    mass = next(e for e in js["effects"] if e["name"] == "mass_error")
    assert mass["params"]["mass_kg"] == rows["mass_kg"]["real"]
    corrected = js["corrected_plant"]
    assert corrected["mass_kg"] == rows["mass_kg"]["real"]
    assert corrected["viscous_n_per_mps"] == js["sim_plant"]["viscous_n_per_mps"]
    assert corrected["coulomb_friction"]["amplitude_n"] == pytest.approx(2.0, rel=0.05)
    assert corrected["cogging"]["pitch_m"] == pytest.approx(0.006, rel=0.01)
    assert corrected["sample_rate_hz"] == 1000.0  # the simulator's plant, changes applied
    assert js["sim_plant"]["std"]["mass_kg"] > 0 and "mass_kg" in js["real_plant"]["std"]
    val = js["fit"]["validation"]
    assert val["nrmse_after"] < 0.5 * val["nrmse_before"]
    text = d.summary()
    assert re.search(r"the real axis is [67]% heavier \(3\.3", text), text
    assert re.search(r"has Coulomb friction of (1\.9|2\.0)\d* N the simulation lacks", text)


@pytest.mark.slow
@pytest.mark.parametrize("drive", ["loop_prbs", "open_multisine_thrust_noise",
                                   "loop_chirp_faster"])
def test_same_physics_under_other_excitation_loop_noise_and_rate(drive: str) -> None:
    """Controls: the simulator's own physics recorded otherwise -- nothing to report."""
    if drive == "loop_prbs":
        real = closed_loop(plant(500.0), 5.0, 5, inject="prbs")
    elif drive == "open_multisine_thrust_noise":
        real = open_loop(plant(500.0, thrust_noise=True), "multisine", 5.0, 4)
    else:
        real = closed_loop(plant(500.0), 4.0, 6, faster=1.5, inject="chirp", amplitude=20.0)
    js = diagnose_sim(_sim(), real, None, FAST).to_dict()
    assert js["effects"] == [] and js["sim_only"] == [], js["changes"]
    assert not [c for c in js["changes"] if c["confidence"] == "high"]


@pytest.mark.slow
def test_what_the_simulation_has_that_the_real_axis_lacks() -> None:
    sim = open_loop(plant(cogging=COGGING, coulomb_friction=CoulombFriction(1.5)),
                    "multisine", 5.0, 7)
    real = closed_loop(plant(500.0), 5.0, 8, inject="chirp", amplitude=20.0)
    d = diagnose_sim(sim, real, None, FAST)
    js = d.to_dict()
    assert {e["name"] for e in js["sim_only"]} == {"cogging", "coulomb_friction"}
    assert js["effects"] == []
    rows = {c["parameter"]: c for c in js["changes"]}
    assert rows["cogging.amplitude_n"]["real"] is None
    assert rows["cogging.amplitude_n"]["sim"] == pytest.approx(0.8, rel=0.10)
    assert "cogging" not in js["corrected_plant"]
    assert "coulomb_friction" not in js["corrected_plant"]
    assert "the simulation has a cogging" in d.summary()


@pytest.mark.slow
def test_an_uncertain_simulation_is_no_evidence_of_a_change() -> None:
    """A short, noisy simulated recording gives an uncertain plant: the real axis' precise
    mass (the same) and its friction (also in the simulator, not resolved by its short
    recording) are judged against both errors, and nothing is reported."""
    noisy = plant(500.0, coulomb_friction=CoulombFriction(0.4),
                  noise=replace(NOISE, speed_std=0.02, force_std=4.0))
    sim = open_loop(noisy, "multisine", 2.0, 9)
    real = open_loop(plant(500.0, coulomb_friction=CoulombFriction(0.4)), "chirp", 10.0, 10)
    d = diagnose_sim(sim, real, None, FAST)
    js = d.to_dict()
    assert js["effects"] == [] and js["sim_only"] == [], js["changes"]
    sim_sd, real_sd = js["sim_plant"]["std"]["mass_kg"], js["real_plant"]["std"]["mass_kg"]
    assert sim_sd > 3 * real_sd


@pytest.mark.slow
def test_cli_jointstate_sim_at_1khz_against_topics_at_500hz(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The simulator as ros2_control publishes it (JointState, 1 kHz), the real drive as
    three topics at 500 Hz; the JSON, the corrected plant file and the report."""
    write_joint_states(tmp_path / "sim", _sim())
    write_recording(tmp_path / "real", _real_with_effects(), namespace="/axis")
    out, plant_file = tmp_path / "d.json", tmp_path / "corrected.yaml"
    rc = main(["diagnose", "--sim", str(tmp_path / "sim"), "--real", str(tmp_path / "real"),
               "--json", str(out), "--corrected-plant", str(plant_file), "--no-gfrf",
               "--report", str(tmp_path / "rep")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "simulator's recording" in text and "side by side:" in text
    assert "heavier" in text
    js = json.loads(out.read_text())
    assert js["reference"] == "sim_recording" and js["sim"] == str(tmp_path / "sim")
    assert {"sim_plant", "sim_only", "changes", "corrected_plant", "effects"} <= set(js)
    assert js["sim_plant"]["sample_rate_hz"] == 1000.0
    p = load_plant(plant_file)
    assert p.coulomb_friction is not None and p.mass_kg == js["corrected_plant"]["mass_kg"]
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "side by side" in page and "heavier" in page
    api = ps.diagnose(None, tmp_path / "real", sim=tmp_path / "sim", gfrf=False)
    assert api.to_dict()["changes"] == js["changes"]


def test_exactly_one_reference(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = "bags/paper_speed_nominal"
    for args in (["--plant", "plants/nominal.yaml", "--sim", bag], []):
        with pytest.raises(SystemExit) as exc:
            main(["diagnose", *args, "--real", bag])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--plant" in err and "--sim" in err
    with pytest.raises(ps.PmsmSysidError, match="not both"):
        ps.diagnose("plants/nominal.yaml", bag, sim=bag)


def test_a_sim_recording_that_cannot_identify_a_plant_says_what_it_needs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = open_loop(plant(500.0), "chirp", 3.0, 2)
    write_recording(tmp_path / "short", rec.window(0, 400))
    still = ps.Recording(t=rec.t, thrust=rec.thrust, speed=0 * rec.t, position=0 * rec.t,
                         sample_rate_hz=500.0)
    write_recording(tmp_path / "still", still)
    for name, words in (("short", "too short to identify a plant"), ("still", "does not move")):
        rc = main(["diagnose", "--sim", str(tmp_path / name), "--real",
                   "bags/paper_speed_nominal", "--json", str(tmp_path / "d.json")])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and len(err.splitlines()) == 1, err
        assert "simulated recording" in err and words in err, err
        assert not (tmp_path / "d.json").exists()
