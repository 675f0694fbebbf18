"""``pmsm-sysid diagnose``: the standard JSON, the report, and one-line errors (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pmsm_sysid.bagio import write_recording
from pmsm_sysid.cli import main
from pmsm_sysid.core.physics.plant import load_plant, plant_from_dict
from pmsm_sysid.core.recording.signals import Recording

REPO = Path(__file__).resolve().parents[1]
NOMINAL = str(REPO / "plants" / "nominal.yaml")
COGGING_BAG = str(REPO / "bags" / "concealed_cogging")

EFFECT_NAMES = {"cogging", "coulomb_friction", "stribeck_friction", "force_offset",
                "thrust_ripple", "thrust_lag", "transport_delay", "spring", "mass_error",
                "viscous_error", "unexplained"}
PARAMS = {"cogging": {"amplitude_n", "pitch_m", "phase_rad", "harmonics"},
          "coulomb_friction": {"amplitude_n"}, "stribeck_friction": {"static_n", "velocity_mps"},
          "force_offset": {"amplitude_n"}, "thrust_ripple": {"relative", "pitch_m"},
          "thrust_lag": {"tau_s"}, "transport_delay": {"delay_s"},
          "spring": {"stiffness_n_per_m"}, "mass_error": {"mass_kg"},
          "viscous_error": {"viscous_n_per_mps"}}


def _check_contract(d: dict) -> None:
    assert set(d) >= {"plant", "mismatch", "effects", "corrected_plant", "fit"}
    assert isinstance(d["mismatch"]["nrmse_before"], float)
    assert {w["axis"] for w in d["mismatch"]["where"]} <= {"position", "velocity",
                                                          "frequency", "time"}
    for e in d["effects"]:
        assert e["name"] in EFFECT_NAMES
        assert {"params", "significance", "explains"} <= set(e)
        assert PARAMS.get(e["name"], set()) <= set(e["params"])
        assert 0.0 <= e["explains"] <= 1.0
    for seg in ("estimation", "validation"):
        assert {"nrmse_before", "nrmse_after"} <= set(d["fit"][seg])
    plant_from_dict(d["corrected_plant"])
    plant_from_dict(d["plant"])


@pytest.mark.slow
def test_diagnose_json_report_and_corrected_plant(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "d.json"
    rc = main(["diagnose", "--plant", NOMINAL, "--real", COGGING_BAG, "--json", str(out),
               "--report", str(tmp_path / "rep"), "--corrected-plant",
               str(tmp_path / "corrected.yaml")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "cogging" in text and "pitch_m" in text and "held-out" in text
    d = json.loads(out.read_text())
    _check_contract(d)
    assert [e["name"] for e in d["effects"]] == ["cogging"]
    cog = d["effects"][0]
    assert cog["params"]["pitch_m"] == pytest.approx(0.007, rel=0.02)
    assert cog["params_std"]["pitch_m"] > 0 and cog["held_out"]["confirmed"]
    assert d["fit"]["validation"]["nrmse_after"] < d["fit"]["validation"]["nrmse_before"]
    # the corrected plant file holds the cogging found and loads like any plant file
    corrected = load_plant(tmp_path / "corrected.yaml")
    assert corrected == plant_from_dict(d["corrected_plant"])
    assert corrected.cogging is not None
    assert corrected.cogging.pitch_m == pytest.approx(cog["params"]["pitch_m"])
    html = (tmp_path / "rep" / "index.html").read_text()
    pngs = sorted(p.name for p in (tmp_path / "rep").glob("*.png"))
    assert {"diagnose_residual_time.png", "diagnose_residual_vs_position.png",
            "diagnose_residual_vs_velocity.png", "diagnose_fit.png"} <= set(pngs)
    assert all(name in html for name in pngs)
    # the named effect has its own section: parameters with units, confidence, evidence,
    # and its before/after figure embedded in the one-file page
    assert "Effect: cogging" in html and "effect_cogging.png" in pngs
    section = html[html.index("Effect: cogging"):]
    assert "confidence" in section and "held-out data" in section and " m</dd>" in section
    assert 'data-file="effect_cogging.png"' in section


def test_json_to_stdout_keeps_the_summary_off_it(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["diagnose", "--plant", NOMINAL, "--real", COGGING_BAG, "--json", "-",
               "--no-replay"])
    assert rc == 0
    cap = capsys.readouterr()
    d = json.loads(cap.out)
    _check_contract(d)
    assert "output_error" not in d["fit"]["estimation"]
    assert "equation-error NRMSE" in cap.err


def _one_line_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    try:
        rc = main(argv)
    except SystemExit as exc:  # usage errors leave through argparse
        rc = int(exc.code or 0)
    err = capsys.readouterr().err
    assert rc == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_bad_inputs_are_one_line_exit_2(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    line = _one_line_error(capsys, ["diagnose", "--plant", str(tmp_path / "none.yaml"),
                                    "--real", COGGING_BAG])
    assert "no such plant file" in line
    bad = tmp_path / "bad.yaml"
    bad.write_text("mass_kg: -1\n")
    assert "mass_kg" in _one_line_error(capsys, ["diagnose", "--plant", str(bad),
                                                 "--real", COGGING_BAG])
    typo = tmp_path / "typo.yaml"
    typo.write_text("mass_kgg: 2.0\n")
    assert "mass_kg" in _one_line_error(capsys, ["diagnose", "--plant", str(typo),
                                                 "--real", COGGING_BAG])
    _one_line_error(capsys, ["diagnose", "--plant", NOMINAL, "--real",
                             str(tmp_path / "nobag")])
    _one_line_error(capsys, ["diagnose", "--plant", NOMINAL])  # usage: --real missing
    _one_line_error(capsys, ["diagnose", "--plant", NOMINAL, "--real", COGGING_BAG,
                             "--alpha", "2"])


def test_unusable_recordings_are_one_line_exit_2(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    n = 60
    t = np.arange(n) / 500.0
    short = Recording(t=t, thrust=np.sin(t * 40), speed=np.cos(t * 40),
                      position=np.sin(t * 40) / 40, sample_rate_hz=500.0)
    write_recording(tmp_path / "short", short)
    line = _one_line_error(capsys, ["diagnose", "--plant", NOMINAL, "--real",
                                    str(tmp_path / "short")])
    assert "too few" in line or "cannot be split" in line
    still = Recording(t=np.arange(3000) / 500.0, thrust=np.zeros(3000), speed=np.zeros(3000),
                      position=np.zeros(3000), sample_rate_hz=500.0)
    write_recording(tmp_path / "still", still)
    line = _one_line_error(capsys, ["diagnose", "--plant", NOMINAL, "--real",
                                    str(tmp_path / "still")])
    assert "does not move" in line


def test_help() -> None:
    with pytest.raises(SystemExit) as exc:
        main(["diagnose", "--help"])
    assert exc.value.code == 0
