"""``pmsm-sysid gfrf``: contract JSON, --at evaluation, support marks, errors as one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pmsm_sysid.cli import main
from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.selection.identifiability import excitation_summary
from pmsm_sysid.core.terms.model import NarxModel

REPO = Path(__file__).resolve().parents[1]
TABLE2 = REPO / "examples" / "paper_table2_speed.json"
R, F0 = 0.95, 0.06


def resonant(extra: dict[str, float] | None = None, **kw: float) -> dict:
    coefs = {"y(k-1)": 2 * R * np.cos(2 * np.pi * F0), "y(k-2)": -R * R, "u(k-1)": 0.5,
             **(extra if extra is not None else {"u(k-1)^2": 0.1, "y(k-1)^3": 0.01})}
    m = NarxModel.from_terms(coefs, sample_rate_hz=500.0)
    return {"input": "thrust", "output": "speed", "sample_rate_hz": 500.0,
            "terms": m.terms_json(), **kw}


def run_cli(tmp_path: Path, model: dict | Path, *extra: str) -> tuple[int, dict | None]:
    if isinstance(model, dict):
        path = tmp_path / "model.json"
        path.write_text(json.dumps(model))
    else:
        path = model
    out = tmp_path / "gfrf.json"
    out.unlink(missing_ok=True)  # outputs are never replaced without --force
    rc = main(["gfrf", str(path), "--json", str(out), *extra])
    return rc, json.loads(out.read_text()) if out.exists() else None


def test_contract_keys_and_at_points(tmp_path: Path) -> None:
    rc, d = run_cli(tmp_path, resonant(), "--at", "0.06", "--at", "0.06,-0.02",
                    "--at", "0.01, 0.02, 0.03")
    assert rc == 0 and d is not None
    for key in ("sample_rate_hz", "stable", "poles", "h1", "h2", "h3", "eval"):
        assert key in d
    assert d["sample_rate_hz"] == 500.0 and d["stable"] is True
    assert sorted(np.hypot(*np.array(d["poles"]).T)) == pytest.approx([R, R])
    peak = d["h1"]["peaks"][0]
    assert {"freq_hz", "freq_norm", "gain_db", "phase_deg", "supported", "note"} <= peak.keys()
    assert peak["freq_hz"] == pytest.approx(500 * peak["freq_norm"])
    assert abs(peak["freq_norm"] - F0) < 2e-3
    for r in d["h2"]["ridges"] + d["h3"]["ridges"]:
        assert {"kind", "freq_hz", "freq_norm", "sign", "supported", "note"} <= r.keys()
        assert r["kind"] in ("f1", "f2", "f1+f2", "f1+f3", "f1+f2+f3") and r["sign"] in (1, -1)
    assert {r["kind"] for r in d["h2"]["ridges"]} >= {"f1+f2"}
    g = Gfrf.from_model(NarxModel.from_dict(resonant()))
    assert [e["f"] for e in d["eval"]] == [[0.06], [0.06, -0.02], [0.01, 0.02, 0.03]]
    for e in d["eval"]:
        h = complex(g.h(*e["f"]))
        assert e["h"] == pytest.approx([h.real, h.imag], abs=1e-12)
        assert e["order"] == len(e["f"])


def test_linear_model_says_h2_h3_zero(tmp_path: Path) -> None:
    rc, d = run_cli(tmp_path, resonant(extra={}), "--at", "0.1,0.2")
    assert rc == 0 and d is not None
    assert d["h2"]["zero"] and d["h3"]["zero"] and d["h2"]["ridges"] == []
    assert "no term of degree" in d["h2"]["note"]
    assert any("no nonlinear terms" in w for w in d["warnings"])
    assert d["eval"][0]["h"] == [0.0, 0.0]


def test_a_constant_term_is_a_note_not_a_warning(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """identify fits a constant term by default: that it does not enter the GFRFs is said
    as a note, so an analysis of a default model carries no warning for it."""
    rc, d = run_cli(tmp_path, resonant(extra={"const": 0.3, "u(k-1)^2": 0.1}))
    assert rc == 0 and d is not None
    assert d["warnings"] == []
    assert d["notes"] == ["the constant term does not enter the GFRFs (it shifts the "
                          "operating point)"]
    out = capsys.readouterr().out
    assert "note: the constant term" in out and "warning" not in out
    rc, d = run_cli(tmp_path, resonant())
    assert rc == 0 and d is not None and d["notes"] == []


def test_unstable_model_reported_and_computed(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                              ) -> None:
    model = {"sample_rate_hz": 500.0,
             "terms": [{"name": "y(k-1)", "estimate": 1.02}, {"name": "u(k-1)", "estimate": 1.0},
                       {"name": "u(k-1)^2", "estimate": 0.1}]}
    rc, d = run_cli(tmp_path, model, "--orders", "1,2")
    assert rc == 0 and d is not None
    assert d["stable"] is False and d["max_pole_radius"] == pytest.approx(1.02)
    assert "UNSTABLE" in capsys.readouterr().out
    assert d["h1"]["peaks"] and d["h3"].get("skipped")


def test_support_marks_from_the_excitation_block(tmp_path: Path) -> None:
    """A tone at the resonance makes the peak unsupported; a multisine covering it does not."""
    tone = excitation_summary(np.sin(2 * np.pi * F0 * np.arange(1000)), 500.0)
    multi = excitation_summary(make_excitation("multisine", 4000, 500.0, seed=3,
                                               f_min_hz=1.0, f_max_hz=60.0), 500.0)
    rc, d = run_cli(tmp_path, resonant(excitation=tone.to_dict()))
    assert rc == 0 and d is not None
    top = d["h1"]["peaks"][0]
    assert top["supported"] is False and "pure-tone" in top["note"]
    assert d["identifiability"]["excitation"]["broadband"] is False
    assert "tonal" in d["identifiability"]["rests_on"]
    near = [r for r in d["h2"]["ridges"] if abs(r["freq_norm"] - F0) < 2e-3]
    assert near and not any(r["supported"] for r in near)
    rc, d = run_cli(tmp_path, resonant(excitation=multi.to_dict()))
    assert d is not None and d["h1"]["peaks"][0]["supported"] is True  # 30 Hz in 1-60 Hz
    rc, d = run_cli(tmp_path, resonant())
    assert d is not None and d["h1"]["peaks"][0]["supported"] is None
    assert d["identifiability"]["excitation"] is None


def test_grid_option(tmp_path: Path) -> None:
    rc, d = run_cli(tmp_path, resonant(), "--grid", "16")
    assert rc == 0 and d is not None
    g = d["grid"]
    assert len(g["h2_db"]) == 16 and len(g["h2_db"][0]) == 16 and len(g["h1_db"]) == 16
    gf = Gfrf.from_model(NarxModel.from_dict(resonant()))
    f = np.array(g["f_norm"])
    assert g["h2_db"][3][9] == pytest.approx(20 * np.log10(abs(gf.h(f[3], f[9]))), abs=1e-3)


def test_run_summary_last_model_is_accepted(tmp_path: Path) -> None:
    rc, d = run_cli(tmp_path, {"samples_received": 10, "last_model": resonant()})
    assert rc == 0 and d is not None and d["h1"]["peaks"]


@pytest.mark.parametrize("args, text", [
    (["--at", "0.7"], "within [-0.5, 0.5]"),
    (["--at", "nan"], "within [-0.5, 0.5]"),
    (["--at", "0.1,x"], "cycles/sample"),
    (["--at", "0.1,0.1,0.1,0.1,0.1"], "1 to 4"),
    (["--grid", "100000"], "grid must be"),
    (["--orders", "4"], "orders"),
])
def test_bad_options_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                     args: list[str], text: str) -> None:
    path = tmp_path / "m.json"
    path.write_text(json.dumps(resonant()))
    with pytest.raises(SystemExit) as exc:
        main(["gfrf", str(path), *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert text in err and "\n" not in err


@pytest.mark.parametrize("content, text", [
    ("{not json", "not valid JSON"),
    ('{"foo": 1}', "not a model JSON"),
    ('{"terms": [{"name": "x(k-1)", "estimate": 1.0}]}', "cannot parse term"),
    ('{"terms": [{"name": "u(k-1)"}]}', "not a model JSON"),
    ('{"terms": [{"name": "u(k-1)", "estimate": 1.0}], "excitation": {"band_hz": 3}}',
     "excitation"),
])
def test_bad_model_files(tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str,
                         text: str) -> None:
    path = tmp_path / "m.json"
    path.write_text(content)
    assert main(["gfrf", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert text in err and "\n" not in err and "Traceback" not in err
    assert main(["gfrf", str(tmp_path / "missing.json")]) == 2


def test_console_script_end_to_end(tmp_path: Path) -> None:
    exe = Path(sys.executable).with_name("pmsm-sysid")
    out = subprocess.run([str(exe), "gfrf", str(TABLE2), "--orders", "1", "--at", "0.0305",
                          "--json", "-"], capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert d["h1"]["peaks"][0]["gain_db"] == pytest.approx(46.4, abs=0.05)
    assert "H1 peaks" in out.stderr  # the human summary goes to stderr with --json -


def test_pole_on_the_unit_circle(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An integrator (position from thrust through y(k-1) = 1): H1(0) is infinite. The tool
    reports it (stable false, null values in JSON, n/a in the text) instead of failing."""
    model = {"sample_rate_hz": 500.0,
             "terms": [{"name": "y(k-1)", "estimate": 1.0}, {"name": "u(k-1)", "estimate": 0.002},
                       {"name": "y(k-1)u(k-1)", "estimate": 0.01}]}
    rc, d = run_cli(tmp_path, model, "--at", "0", "--at", "0.1")
    assert rc == 0 and d is not None
    assert d["stable"] is False and d["max_pole_radius"] == pytest.approx(1.0)
    assert d["eval"][0]["h"] == [None, None] and d["eval"][0]["gain_db"] is None
    z = np.exp(-2j * np.pi * 0.1)
    h = 0.002 * z / (1 - z)
    assert d["eval"][1]["h"] == pytest.approx([h.real, h.imag], abs=1e-15)
    assert d["h1"]["peaks"][0]["kind"] == "dc" and d["h1"]["peaks"][0]["gain_db"] is None
    captured = capsys.readouterr()
    assert "n/a" in captured.out and "Warning" not in captured.err


def test_complex_values_carry_their_sign_and_counts_their_plural() -> None:
    """H at a frequency prints as a + bj or a - bj (it printed '4.25635e-08 1.1799e-07j',
    no sign); one pole is '1 pole'."""
    from pmsm_sysid.cli.gfrf import complex_text, plural

    assert complex_text(4.25635e-08, 1.1799e-07) == "4.25635e-08 + 1.1799e-07j"
    assert complex_text(0.000105325, -0.00409568) == "0.000105325 - 0.00409568j"
    assert complex_text(None, 1.0) == "n/a 1j"
    assert (plural(1, "pole"), plural(28, "pole"), plural(0, "pole")) == (
        "1 pole", "28 poles", "0 poles")
