"""``pmsm-sysid simulate``: bags equal the offline simulation; bad input is one line, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_inprocess import invoke
from reliability_helpers import assert_one_line_error

from pmsm_sysid.bagio import read_recording
from pmsm_sysid.cli import main
from pmsm_sysid.cli import simulate as simulate_cli
from pmsm_sysid.core.physics.excitation import EXCITATIONS, make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant

REPO = Path(__file__).resolve().parents[1]


def test_bag_equals_offline_simulation(tmp_path: Path) -> None:
    bag, summary = tmp_path / "bag", tmp_path / "summary.json"
    proc = invoke("simulate", "--plant", str(REPO / "plants" / "cogging.yaml"), "--duration",
                   "2", "--seed", "4", "--out", str(bag), "--json", str(summary))
    assert proc.returncode == 0, proc.stderr
    assert "1000 samples at 500 Hz" in proc.stdout
    plant = load_plant(REPO / "plants" / "cogging.yaml")
    want = simulate(plant, make_excitation("paper-speed", 1000, 500.0), seed=4)
    got = read_recording(bag).recording
    assert len(got) == 1000
    for name in ("thrust", "speed", "position"):
        np.testing.assert_array_equal(got.signal(name), want.signal(name))
    np.testing.assert_allclose(got.t, want.t, rtol=0, atol=1e-9)
    assert not got.speed_derived
    info = json.loads(summary.read_text())
    assert info["samples"] == 1000 and info["effects"] == ["cogging", "noise"]
    assert info["plant"]["cogging"]["pitch_m"] == 0.005
    # seconds of data per second of work, as the summary's own times give it (how fast is a
    # benchmark's question: bench/, not a test that a busy machine fails)
    assert info["realtime_factor"] == pytest.approx(2.0 / info["total_s"], rel=1e-9)
    assert 0 < info["simulate_s"] <= info["total_s"]
    assert info["speed_rms_mps"] == pytest.approx(float(np.std(want.speed)))


@pytest.mark.parametrize("kind", ["paper-position", "multisine", "chirp", "prbs", "aprbs"])
def test_every_excitation_and_sqlite3(tmp_path: Path, kind: str,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "bag"
    rc = main(["simulate", "--excitation", kind, "--duration", "1", "--seed", "2", "--out",
               str(bag), "--storage", "sqlite3", "--amplitude", "12", "--json", "-"])
    assert rc == 0
    out = capsys.readouterr()
    info = json.loads(out.out)            # stdout is pure JSON with --json -
    assert "wrote" in out.err
    assert info["excitation"] == kind and info["amplitude_n"] == 12.0
    assert list(bag.glob("*.db3"))
    got = read_recording(bag).recording
    np.testing.assert_array_equal(got.thrust, make_excitation(kind, 500, 500.0, seed=2,
                                                              amplitude_n=12.0))


def test_excitation_options_and_namespace(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    rc = main(["simulate", "--excitation", "multisine", "--excitation-option", "f_max_hz=20",
               "--excitation-option", "phases=schroeder", "--duration", "1", "--out", str(bag),
               "--namespace", "/axis1"])
    assert rc == 0
    got = read_recording(bag, namespace="/axis1").recording
    np.testing.assert_array_equal(got.thrust, make_excitation(
        "multisine", 500, 500.0, f_max_hz=20, phases="schroeder"))


def test_refuses_to_overwrite_unless_forced(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    assert main(["simulate", "--duration", "0.5", "--out", str(bag)]) == 0
    before = sorted((p.name, p.stat().st_mtime_ns) for p in bag.iterdir())
    proc = invoke("simulate", "--duration", "0.5", "--out", str(bag))
    assert_one_line_error(proc, "exists already; use --force")
    assert sorted((p.name, p.stat().st_mtime_ns) for p in bag.iterdir()) == before
    assert main(["simulate", "--duration", "0.5", "--seed", "1", "--out", str(bag),
                 "--force", "--plant", str(REPO / "plants" / "nominal_noisy.yaml")]) == 0
    assert read_recording(bag).recording.meta.get("pmsm_sysid.seed") == "1"
    plain = tmp_path / "notabag"
    plain.mkdir()
    (plain / "precious.txt").write_text("keep me")
    assert main(["simulate", "--duration", "0.5", "--out", str(plain), "--force"]) == 2
    assert (plain / "precious.txt").read_text() == "keep me"


@pytest.mark.parametrize(("plant_text", "fragment"), [
    ("mass_kg: 2.0\nviscus_n_per_mps: 30\n",
     "unknown key 'viscus_n_per_mps' (did you mean 'viscous_n_per_mps'?)"),
    ("mass_kg: .nan\n", "mass_kg must be finite"),
    ("cogging: {amplitude_n: 3}\n", "cogging is missing pitch_m"),
    ("mass_kg: [2\n", "not valid YAML"),
])
def test_bad_plant_file_exit_2_one_line(tmp_path: Path, plant_text: str, fragment: str) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(plant_text)
    proc = invoke("simulate", "--plant", str(plant), "--out", str(tmp_path / "bag"))
    assert_one_line_error(proc, fragment)
    assert not (tmp_path / "bag").exists()


def test_bad_arguments_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "bag")
    assert main(["simulate", "--plant", str(tmp_path / "missing.yaml"), "--out", out]) == 2
    assert "no such plant file" in capsys.readouterr().err
    assert main(["simulate", "--excitation-option", "f9=1", "--excitation", "chirp",
                 "--out", out]) == 2
    assert "unknown option(s) f9" in capsys.readouterr().err
    for bad in (["--duration", "-1"], ["--duration", "nan"], ["--excitation", "sine"],
                ["--excitation-option", "novalue"], ["--storage", "zip"]):
        with pytest.raises(SystemExit) as info:
            main(["simulate", "--out", out, *bad])
        assert info.value.code == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not Path(out).exists()


def test_cli_lists_the_core_excitations() -> None:
    assert simulate_cli.EXCITATIONS == EXCITATIONS


SAMPLE_BAGS = {"paper_speed_nominal": "nominal_noisy.yaml",
               "paper_speed_cogging": "cogging.yaml", "paper_speed_coulomb": "coulomb.yaml"}


def test_sample_bags_are_small_and_regenerable() -> None:
    """bags/ holds what scripts/make_bags.sh makes with today's simulator (sample for sample)."""
    def size(path: Path) -> int:
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())

    assert sum(size(REPO / "bags" / name) for name in SAMPLE_BAGS) < 5e6
    assert size(REPO / "bags") < 12e6  # with the sim-to-real and sim-against-drive bags
    for name, plant_file in SAMPLE_BAGS.items():
        loaded = read_recording(REPO / "bags" / name)
        rec = loaded.recording
        assert len(rec) >= 4000 and rec.sample_rate_hz == pytest.approx(500.0)
        assert loaded.report is not None
        assert rec.meta["pmsm_sysid.plant_file"] == f"plants/{plant_file}"
        want = simulate(load_plant(REPO / "plants" / plant_file),
                        make_excitation("paper-speed", len(rec), 500.0), seed=1)
        for signal in ("thrust", "speed", "position"):
            np.testing.assert_array_equal(rec.signal(signal), want.signal(signal),
                                          err_msg=f"{name}: run scripts/make_bags.sh")
    assert "make_bags.sh" in (REPO / "bags" / "README.md").read_text()
