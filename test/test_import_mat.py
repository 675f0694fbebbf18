"""`pmsm-sysid import-mat`: the EMPS recording as a contract bag, equal to the .mat columns."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from cli_inprocess import invoke
from conftest import EMPS_MAT
from rosbags.highlevel import AnyReader

from pmsm_sysid.bagio import read_recording
from pmsm_sysid.cli import main


@pytest.fixture(scope="module")
def emps() -> dict[str, np.ndarray]:
    assert EMPS_MAT.is_file(), f"EMPS data missing at {EMPS_MAT}"
    return {k: v for k, v in scipy.io.loadmat(str(EMPS_MAT)).items() if not k.startswith("__")}


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_emps_import_equals_mat_columns(tmp_path: Path, emps: dict[str, np.ndarray],
                                       storage: str, capsys: pytest.CaptureFixture[str]) -> None:
    bag, summary = tmp_path / "emps", tmp_path / "s.json"
    assert main(["import-mat", str(EMPS_MAT), "--out", str(bag), "--storage", storage,
                 "--json", str(summary)]) == 0
    assert "24841 samples at 1000 Hz" in capsys.readouterr().out
    t, qm, qg = (emps[k].ravel() for k in ("t", "qm", "qg"))
    force = emps["gtau"].item() * emps["vir"].ravel()
    loaded = read_recording(bag)
    rec = loaded.recording
    assert len(rec) == 24841 and rec.sample_rate_hz == pytest.approx(1000.0, abs=1e-9)
    np.testing.assert_array_equal(rec.thrust, force)      # exact float64 equality
    np.testing.assert_array_equal(rec.position, qm)
    assert np.max(np.abs(rec.t - t)) <= 0.5e-9            # stamps are integer nanoseconds
    assert rec.speed_derived and loaded.report.speed_derived
    np.testing.assert_array_equal(rec.speed[1:], np.diff(qm) / np.diff(rec.t))  # causal
    assert rec.speed[0] == rec.speed[1]
    assert loaded.report.n_unaligned == 0 and loaded.report.n_gaps == 0
    assert "/pmsm/speed" not in loaded.topics
    assert rec.meta["pmsm_sysid.speed"].startswith("absent: derived")
    assert float(rec.meta["pmsm_sysid.gtau"]) == emps["gtau"].item()
    with AnyReader([bag]) as reader:  # the reference position, by a stock reader
        conns = [c for c in reader.connections if c.topic == "/pmsm/reference"]
        ref = [reader.deserialize(raw, c.msgtype).point.x for c, _, raw in reader.messages(conns)]
    np.testing.assert_array_equal(ref, qg)
    info = json.loads(summary.read_text())
    assert info["samples"] == 24841 and info["speed_derived"] is True
    assert info["align"]["n_aligned"] == 24841


def _mat(tmp_path: Path, **arrays: object) -> Path:
    path = tmp_path / "x.mat"
    scipy.io.savemat(str(path), arrays)
    return path


def _case(tmp_path: Path, case: str) -> list[str]:
    n = 50
    t = np.arange(n) / 1000.0
    good = {"t": t[:, None], "qm": np.sin(t)[:, None], "qg": np.sin(t)[:, None],
            "vir": np.cos(t)[:, None], "gtau": np.array([[35.0]])}
    out = str(tmp_path / "bag")
    if case == "missing":
        return [str(tmp_path / "nope.mat"), "--out", out]
    if case == "directory":
        return [str(tmp_path), "--out", out]
    if case == "text":
        (tmp_path / "x.mat").write_text("not matlab")
        return [str(tmp_path / "x.mat"), "--out", out]
    if case == "keys":
        return [str(_mat(tmp_path, t=t, qm=t)), "--out", out]
    if case == "shape":
        return [str(_mat(tmp_path, **{**good, "qm": np.zeros((n - 1, 1))})), "--out", out]
    if case == "nan":
        bad = np.sin(t)
        bad[7] = np.nan
        return [str(_mat(tmp_path, **{**good, "qm": bad[:, None]})), "--out", out]
    if case == "gtau":
        return [str(_mat(tmp_path, **{**good, "gtau": np.ones((2, 1))})), "--out", out]
    if case == "gtau_inf":  # once read as "only 0 samples align"
        return [str(_mat(tmp_path, **{**good, "gtau": np.array([[np.inf]])})), "--out", out]
    if case == "overflow":
        return [str(_mat(tmp_path, **{**good, "gtau": np.array([[1e300]]),
                                     "vir": 1e10 * np.cos(t)[:, None]})), "--out", out]
    if case == "time":
        return [str(_mat(tmp_path, **{**good, "t": t[::-1, None]})), "--out", out]
    assert case == "exists"
    (tmp_path / "bag").mkdir()
    return [str(_mat(tmp_path, **good)), "--out", out]


@pytest.mark.parametrize("case,pattern", [
    ("missing", "no such .mat file"), ("directory", "is a directory"),
    ("text", "not a readable MATLAB .mat file"), ("keys", "missing key(s) vir, gtau"),
    ("shape", "'qm' must be a vector of 50 samples"), ("nan", "'qm' has non-finite"),
    ("gtau", "'gtau' must be a scalar"), ("time", "not strictly increasing"),
    ("gtau_inf", "'gtau' is not finite (inf); it must be a finite gain (thrust = gtau * vir)"),
    ("overflow", "thrust = gtau * vir overflows"),
    ("exists", "exists already"),
])
def test_bad_mat_one_line_exit_2(tmp_path: Path, case: str, pattern: str,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["import-mat", *_case(tmp_path, case)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pmsm-sysid import-mat: error: ") and pattern in err, err
    assert len(err.strip().splitlines()) == 1


def test_small_good_mat_round_trip(tmp_path: Path) -> None:
    args = _case(tmp_path, "exists")
    (tmp_path / "bag").rmdir()
    assert main(["import-mat", *args]) == 0
    rec = read_recording(tmp_path / "bag").recording
    np.testing.assert_array_equal(rec.thrust, 35.0 * np.cos(np.arange(50) / 1000.0))


def test_console_script_exit_2_and_help(tmp_path: Path) -> None:
    script = str(Path(sys.executable).with_name("pmsm-sysid"))
    out = subprocess.run([script, "import-mat", str(tmp_path / "nope.mat"), "--out",
                          str(tmp_path / "b")], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip() == f"pmsm-sysid import-mat: error: {tmp_path / 'nope.mat'}: " \
                                 "no such .mat file"
    helped = invoke("import-mat", "--help")  # the help text is main's: no second process
    assert helped.returncode == 0 and "--out" in helped.stdout
