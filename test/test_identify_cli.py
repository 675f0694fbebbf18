"""``pmsm-sysid identify BAG``: contract JSON, seed-layout table, errors as one line + exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from narx_systems import QUADRATIC, names, simulate, white_input

from pmsm_sysid.bagio import write_recording
from pmsm_sysid.cli import main
from pmsm_sysid.core.recording.signals import Recording

REPO = Path(__file__).resolve().parents[1]
FS = 500.0


def _bag(path: Path, thrust: np.ndarray, speed: np.ndarray) -> Path:
    n = len(thrust)
    rec = Recording(t=np.arange(n) / FS, thrust=thrust, speed=speed,
                    position=np.cumsum(speed) / FS, sample_rate_hz=FS, source="test")
    write_recording(path, rec)
    return path


@pytest.fixture(scope="module")
def narx_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    u = white_input(3200, seed=11)
    y = simulate(QUADRATIC, u, noise_std=1e-3, seed=11)
    return _bag(tmp_path_factory.mktemp("bags") / "narx", u, y)


def test_known_system_json_follows_the_contract(narx_bag: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "model.json"
    rc = main(["identify", str(narx_bag), "--ny", "2", "--nu", "2", "--terms", "5",
               "--estimate", "0:1500", "--validate", "1500:3200", "--json", str(out)])
    assert rc == 0
    d = json.loads(out.read_text())
    assert {"input", "output", "sample_rate_hz", "structure", "terms", "validation",
            "timing_ms", "method", "criterion", "excitation"} <= set(d)
    assert (d["input"], d["output"], d["sample_rate_hz"]) == ("thrust", "speed", 500.0)
    assert d["structure"] == {"ny": 2, "nu": 2, "degree": 2, "delay": 1, "constant": True,
                              "n_candidates": 15}
    assert (d["method"], d["criterion"]) == ("iofr", "terms")
    got = {t["name"]: t for t in d["terms"]}
    assert set(got) - {"const"} == names(QUADRATIC)
    for n, v in QUADRATIC.items():
        assert got[n]["estimate"] == pytest.approx(v, rel=0.01)
        assert 0 < got[n]["std"] < 0.01 and 0 <= got[n]["err"] <= 1
    assert sum(t["err"] for t in d["terms"]) == pytest.approx(d["sum_err"])
    v = d["validation"]
    assert {"nmse", "r2"} <= set(v["estimation"])
    assert {"nmse", "r2", "osa_r2"} <= set(v["validation"])
    assert v["validation"]["r2"] > 0.99
    assert set(v["correlation_tests"]) == {"ee", "ue", "u2e", "u2e2", "e_eu"}
    for t in v["correlation_tests"].values():
        assert {"max_abs", "band", "pass"} <= set(t)
    assert v["correlation_all_pass"] is True
    assert set(d["timing_ms"]) >= {"regressors", "selection", "total"}
    assert d["excitation"]["broadband"] is True
    printed = capsys.readouterr().out
    assert "Model term" in printed and "Std. dev." in printed and "ERR" in printed
    assert "y(k-1)u(k-2)" in printed and "correlation tests" in printed
    # each test's line says what its pass rests on: the lags outside the band, how many
    # white residuals may put there, the largest value and its limit (from the JSON)
    ee = v["correlation_tests"]["ee"]
    assert (ee["n_lags"], ee["n_allowed"]) == (20, 4) and ee["max_allowed"] > ee["band"]
    assert (f"  ee    pass  {ee['n_outside']} of 20 lags outside (4 allowed), largest "
            f"{ee['max_abs']:.3f} (limit {ee['max_allowed']:.3f})") in printed
    assert f"95 % band +-{ee['band']:.3f}; pass: no more lags outside" in printed


def test_json_to_stdout_keeps_stdout_clean(narx_bag: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["identify", str(narx_bag), "--ny", "2", "--nu", "2", "--terms", "5",
               "--method", "ofr", "--criterion", "bic", "--estimate", "0:1500",
               "--no-validate", "--json", "-"])
    assert rc == 0
    cap = capsys.readouterr()
    d = json.loads(cap.out)
    assert d["validation"]["validation"] is None and d["criterion"] == "bic"
    assert "Model term" in cap.err


@pytest.mark.parametrize("argv,message", [
    (["--estimate", "3000:4000"], "outside the recording"),
    (["--validate", "3000:9000"], "outside the recording"),
    (["--estimate", "0:10", "--no-validate"], "too few"),
    (["--estimate", "0:40", "--no-validate"], "correlation tests need"),
    (["--terms", "0"], "--terms: must be >= 1"),
])
def test_bad_requests_exit_2_with_one_line(narx_bag: Path, argv: list[str], message: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    try:
        rc = main(["identify", str(narx_bag), "--ny", "2", "--nu", "2", *argv])
    except SystemExit as exc:  # refused while parsing the options
        rc = exc.code
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err


def test_constant_input_and_missing_bag(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    bag = _bag(tmp_path / "flat", np.full(4000, 2.0), white_input(4000))
    assert main(["identify", str(bag), "--ny", "2", "--nu", "2"]) == 2
    assert "constant" in capsys.readouterr().err
    assert main(["identify", str(tmp_path / "nope")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    with pytest.raises(SystemExit) as exc:
        main(["identify", str(bag), "--method", "magic"])
    assert exc.value.code == 2


@pytest.mark.slow
def test_paper_protocol_on_the_simulated_motor(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Defaults = the paper's speed case on the nominal noisy motor; then the position case."""
    bag = tmp_path / "speed"
    assert main(["simulate", "--plant", str(REPO / "plants" / "nominal_noisy.yaml"),
                 "--out", str(bag), "--duration", "8.2"]) == 0
    out = tmp_path / "speed.json"
    assert main(["identify", str(bag), "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["structure"]["n_candidates"] == 2556
    assert len(d["terms"]) == 16 and d["terms"][0]["name"] == "const"
    assert d["validation"]["validation"]["r2"] > 0.99
    assert d["data_check"]["pe_order"] == 2  # single 16.5 Hz tone: flagged, not refused
    assert d["data_check"]["warnings"]
    assert d["excitation"]["broadband"] is False
    assert abs(d["excitation"]["tones_hz"][0] - 16.5) < 0.5
    out2 = tmp_path / "position.json"
    assert main(["identify", str(bag), "--output", "position", "--ny", "10", "--nu", "10",
                 "--json", str(out2)]) == 0
    d2 = json.loads(out2.read_text())
    assert d2["output"] == "position" and d2["structure"]["n_candidates"] == 231
    capsys.readouterr()
