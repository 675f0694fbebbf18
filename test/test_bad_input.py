"""Bad input, class by class: exit 2 with one line naming the problem, checked before any
work starts, nothing written, nothing already there changed (docs/reliability.md's table).

Everything runs ``main()`` in this process (fast). The output-path cases give each verb an
input that does not exist as well: the answer naming the *output* proves the outputs were
checked before the input was even opened.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from reliability_helpers import SMALL, bag_of, cli_error, known_data

from pmsm_sysid.cli import main
from pmsm_sysid.cli.common import write_json
from pmsm_sysid.core.errors import OutputError
from pmsm_sysid.validate import atomic_write_text


def snapshot(root: Path) -> dict[str, str]:
    """Every path under ``root`` with a hash of its content ('dir' for directories)."""
    out = {}
    for p in sorted(root.rglob("*")):
        out[str(p.relative_to(root))] = ("dir" if p.is_dir() else
                                         hashlib.sha256(p.read_bytes()).hexdigest())
    return out


def unwritable(tmp_path: Path) -> Path:
    """A directory nobody may create files in (sysfs refuses even root)."""
    if os.geteuid() == 0:
        return Path("/sys")
    d = tmp_path / "locked"
    d.mkdir()
    d.chmod(0o500)
    return d


# verb argv (with {missing}: an input that does not exist, {fresh}: an empty directory where
# a valid output may go), the output option under test, and what it holds
OUTPUTS = [
    (["identify", "{missing}"], "--json", "file"),
    (["gfrf", "{missing}"], "--json", "file"),
    (["report", "{missing}", "--out", "{fresh}/r"], "--json", "file"),
    (["report", "{missing}"], "--out", "report"),
    (["simulate", "--plant", "{missing}", "--out", "{fresh}/b"], "--json", "file"),
    (["simulate", "--plant", "{missing}"], "--out", "bag"),
    (["import-mat", "{missing}", "--out", "{fresh}/b"], "--json", "file"),
    (["import-mat", "{missing}"], "--out", "bag"),
    (["diagnose", "--plant", "{missing}", "--real", "{missing}"], "--json", "file"),
    (["diagnose", "--plant", "{missing}", "--real", "{missing}"], "--corrected-plant", "file"),
    (["diagnose", "--plant", "{missing}", "--real", "{missing}"], "--report", "report"),
    (["run", "--plant", "{missing}"], "--json", "file"),
    (["run", "--plant", "{missing}"], "--record", "bag"),
    (["run", "--plant", "{missing}"], "--report", "report"),
    (["record", "--out", "{fresh}/b", "--duration", "1"], "--json", "file"),
    (["record", "--duration", "1"], "--out", "bag"),
    (["replay", "{missing}"], "--json", "file"),
    (["monitor", "--once", "--duration", "1"], "--json", "file"),
]
PLACES = ["missing-dir", "a-directory", "exists", "exists-force-not-ours", "unwritable"]


def _place(tmp_path: Path, kind: str, place: str) -> tuple[str, list[str], str]:
    """(path, extra argv, fragment of the answer) for one bad output place."""
    if place == "missing-dir":
        return str(tmp_path / "nodir" / "x"), [], "does not exist (create it first)"
    if place == "a-directory":
        d = tmp_path / "adir"
        d.mkdir(exist_ok=True)
        (d / "keep.txt").write_text("mine\n")
        if kind == "file":
            return str(d), [], "is a directory"
        return str(d), ["--force"], "not replacing it"
    if place == "exists":
        if kind == "file":
            f = tmp_path / "old.json"
            f.write_text('{"old": true}\n')
            return str(f), [], "exists already; use --force"
        d = tmp_path / "old"
        d.mkdir(exist_ok=True)
        (d / ("metadata.yaml" if kind == "bag" else "index.html")).write_text("old\n")
        return str(d), [], "exists already; use --force"
    if place == "exists-force-not-ours":
        f = tmp_path / "precious.txt"
        f.write_text("precious\n")
        return str(f), ["--force"], "not replacing it" if kind != "file" else ""
    return str(unwritable(tmp_path) / "x"), [], "cannot write in"


# a regular file is a file output's own kind: --force replaces it (no "not ours" case)
CASES = [(a, o, k, p) for a, o, k in OUTPUTS for p in PLACES
         if not (k == "file" and p == "exists-force-not-ours")]


LIVE_VERBS = ("run", "record", "replay", "monitor")  # need ROS: they say so before anything


@pytest.mark.parametrize("argv,option,kind,place", [
    pytest.param(a, o, k, p, id=f"{a[0]}{o}-{p}",
                 marks=[pytest.mark.ros] if a[0] in LIVE_VERBS else []) for a, o, k, p in CASES])
def test_every_output_is_checked_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  argv: list[str], option: str, kind: str,
                                                  place: str) -> None:
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    target, extra, fragment = _place(tmp_path, kind, place)
    before = snapshot(tmp_path)
    args = [a.replace("{missing}", str(tmp_path / "missing.x")).replace("{fresh}", str(fresh))
            for a in argv]
    line = cli_error(capsys, [*args, option, target, *extra], option, fragment)
    assert "missing.x" not in line  # the output was checked first, before the input
    assert snapshot(tmp_path) == before  # nothing written, nothing changed


def test_two_outputs_on_one_path(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cli_error(capsys, ["simulate", "--out", str(tmp_path / "o"), "--json", str(tmp_path / "o")],
              "--out and --json name the same path")


def test_results_are_replaced_only_with_force(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out, summary = tmp_path / "bag", tmp_path / "s.json"
    assert main(["simulate", "--duration", "1", "--out", str(out), "--json", str(summary)]) == 0
    first = snapshot(tmp_path)
    cli_error(capsys, ["simulate", "--duration", "2", "--out", str(out)], "--out", "exists")
    assert snapshot(tmp_path) == first
    assert main(["simulate", "--duration", "2", "--out", str(out), "--json", str(summary),
                 "--force"]) == 0
    assert json.loads(summary.read_text())["samples"] == 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag", "s.json"]  # no temp left
    assert sorted(p.name for p in out.iterdir()) == ["bag.mcap", "metadata.yaml"]


def test_atomic_write_leaves_the_old_file_or_the_new_one(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "r.json"
    target.write_text("old\n")

    def fail(*_: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OutputError, match=r"cannot write \(No space left on device"):
        atomic_write_text(target, "new\n", "--json")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # the temporary is gone


def test_a_result_that_cannot_be_written_at_the_end_is_saved_elsewhere(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path / "spare"))
    (tmp_path / "spare").mkdir()
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", None)
    gone = tmp_path / "gone"  # checked at the start, then removed during a long run
    with pytest.raises(OutputError) as info:
        write_json({"summary": 1}, str(gone / "run.json"))
    spare = Path(str(info.value).rsplit("saved to ", 1)[1].split(" ")[0])
    assert json.loads(spare.read_text()) == {"summary": 1}
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------------------- plant files

DEEP = "a: " + "[" * 5000 + "]" * 5000 + "\n"
HARMONICS = "cogging:\n  amplitude_n: 1\n  pitch_m: 0.03\n  harmonics:\n" + \
    "".join(f"  - {{order: {k}, amplitude_n: 0.1}}\n" for k in range(1, 80))


@pytest.mark.parametrize("text,fragment", [
    (DEEP, "nested too deeply"),
    ("mass_kg: true\n", "mass_kg must be a number, got True"),
    ("mass_kg: '2.0'\n", "mass_kg must be a number, got '2.0'"),
    ("mass_kg: .nan\n", "mass_kg must be finite"),
    ("viscous_n_per_mps: .inf\n", "viscous_n_per_mps must be finite"),
    ("mass_kg: 1e20\n", "mass_kg must be > 0 and <= 10000"),
    ("sample_rate_hz: 1e9\n", "sample_rate_hz must be >= 1 and <= 100000"),
    ("sample_rate_hz: 0.001\n", "sample_rate_hz must be >= 1"),
    ("substeps: 100000\n", "substeps must be >= 1 and <= 4096"),
    ("cogging: {amplitude_n: 1, pitch_m: 0.03, harmonics: [{order: 100000000, amplitude_n: 1}]}\n",
     "cogging.harmonics[0].order must be >= 1 and <= 1000"),
    (HARMONICS, "cogging.harmonics lists 79 entries, at most 64"),
    ("cogging: {amplitude_n: 1, pitch_m: 0.03, harmonics: [{order: 2, amplitude_n: yes}]}\n",
     "cogging.harmonics[0].amplitude_n must be a number, got True"),
    ("cogging: {enabled: 1, amplitude_n: 1, pitch_m: 0.03}\n",
     "cogging.enabled must be true or false"),
    ("spring: yes\n", "spring must be a mapping"),
    ("noise: {speed_std: -1}\n", "noise.speed_std must be >= 0"),
    ("thrust_lag: {tau_s: soon}\n", "thrust_lag.tau_s must be a number, got 'soon'"),
    ("thrust_ripple: {relative: 1, pitch_m: 0.03}\n", "thrust_ripple.relative must be between -1"),
    ("mas_kg: 2\n", "unknown key 'mas_kg' (did you mean 'mass_kg'?)"),
    ("- 1\n- 2\n", "must be a YAML mapping"),
    ("mass_kg: [1\n", "not valid YAML at line"),
])
def test_bad_plant_files(tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str,
                         fragment: str) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text(text)
    before = snapshot(tmp_path)
    cli_error(capsys, ["simulate", "--plant", str(plant), "--out", str(tmp_path / "b")],
              str(plant), fragment)
    assert snapshot(tmp_path) == before


def test_binary_and_huge_plant_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    binary = tmp_path / "b.yaml"
    binary.write_bytes(bytes(range(256)) * 4)
    cli_error(capsys, ["simulate", "--plant", str(binary), "--out", str(tmp_path / "o")],
              "cannot read plant file")
    huge = tmp_path / "h.yaml"
    huge.write_text("# " + "x" * (2 << 20) + "\n")
    cli_error(capsys, ["simulate", "--plant", str(huge), "--out", str(tmp_path / "o")],
              "too large for a plant file")


# ----------------------------------------------------------------------------- CLI numbers


@pytest.mark.parametrize("argv,fragment", [
    (["simulate", "--duration", "inf"], "--duration: must be a finite number"),
    (["simulate", "--out", "x", "--duration", "1e12"], "more than the limit of 10000000"),
    (["simulate", "--duration", "nan"], "--duration"),
    (["simulate", "--seed", "-1"], "--seed: must be >= 0"),
    (["simulate", "--seed", "1.5"], "--seed: must be an integer"),
    (["simulate", "--amplitude", "1e300"], "--amplitude: must be at most 1e+06 N"),
    (["simulate", "--amplitude", "-1"], "--amplitude: must be >= 0"),
    (["run", "--duration", "inf"], "--duration: must be a finite number"),
    (["run", "--duration", "1e12"], "--duration: must be at most 1e+06 s"),
    (["run", "--seed", "-3"], "--seed: must be >= 0"),
    (["run", "--hop", "0"], "--hop: must be >= 1"),
    (["run", "--hop", "-5"], "--hop: must be >= 1"),
    (["run", "--window", "1"], "--window: must be >= 2"),
    (["run", "--wait", "inf"], "--wait: must be a finite number"),
    (["run", "--rate", "nan"], "--rate: must be a number, got nan"),
    (["record", "--out", "x", "--depth", "0"], "--depth: must be >= 1"),
    (["record", "--out", "x", "--duration", "-1"], "--duration: must be > 0"),
    (["monitor", "--interval", "0"], "--interval: must be > 0"),
    (["replay", "b", "--loop", "-1"], "--loop: must be >= 0"),
    (["replay", "b", "--burst", "0"], "--burst: must be >= 1"),
    (["identify", "b", "--terms", "0"], "--terms: must be >= 1"),
    (["identify", "b", "--terms", "-4"], "--terms: must be >= 1"),
    (["identify", "b", "--ny", "1e9"], "--ny: must be an integer"),
    (["identify", "b", "--ny", "100000"], "--ny: must be at most 10000"),
    (["identify", "b", "--corr-lags", "0"], "--corr-lags: must be >= 1"),
    (["identify", "b", "--estimate", "10:5"], "need 0 <= START < STOP, got '10:5'"),
    (["identify", "b", "--estimate=-5:5"], "need 0 <= START < STOP"),
    (["identify", "b", "--validate", "7:7"], "need 0 <= START < STOP"),
    (["identify", "b", "--rho", "inf"], "--rho"),
    (["gfrf", "m", "--grid", "0"], "grid must be 2.."),
    (["gfrf", "m", "--at", "nan"], "must be finite"),
    (["diagnose", "--plant", "p", "--real", "b", "--alpha", "0"], "--alpha"),
])
def test_impossible_numbers(capsys: pytest.CaptureFixture[str], argv: list[str],
                            fragment: str) -> None:
    cli_error(capsys, argv, fragment)


def test_identifier_that_no_window_can_fit_is_refused_at_start(
        capsys: pytest.CaptureFixture[str]) -> None:
    from pmsm_sysid.core.errors import DataError
    from pmsm_sysid.core.online.tracker import tracker_config
    from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS as DEFAULTS

    p = dict(DEFAULTS)
    p["speed.ny"] = 990  # 990 lags + 2 x 16 parameters > 1000 samples
    with pytest.raises(DataError, match="can never fit maximum lag 990"):
        tracker_config(p)


# ----------------------------------------------------------------------------- names


@pytest.mark.parametrize("name", ["bad ns", "/a//b", "/x/", "1pmsm", "/pm-sm", "~/x",
                                  "/{node}", "", "/" + "a" * 300])
@pytest.mark.parametrize("verb", [["run"], ["monitor"], ["record", "--out", "x"],
                                  ["simulate", "--out", "x"], ["identify", "b"],
                                  ["import-mat", "m", "--out", "x"],
                                  ["diagnose", "--plant", "p", "--real", "b"],
                                  ["replay", "b"]])
def test_invalid_ros_names_refused_before_rclpy(capsys: pytest.CaptureFixture[str],
                                                verb: list[str], name: str) -> None:
    cli_error(capsys, [*verb, "--namespace", name], "--namespace")


# ----------------------------------------------------------------------------- JSON inputs


@pytest.mark.parametrize("content,fragment", [
    (b"{not json", "not valid JSON"),
    (b"[1, 2, 3]", "the JSON is a list"),
    (b'"a model"', "the JSON is a string"),
    (b"null", "the JSON is null"),
    (b"42", "the JSON is a number"),
    (b"[" * 100000 + b"]" * 100000, "nested too deeply"),
    (bytes(range(256)), "not a text file"),
    (b"", "not valid JSON"),
])
@pytest.mark.parametrize("verb", ["gfrf", "report"])
def test_malformed_json_inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str], verb: str,
                               content: bytes, fragment: str) -> None:
    src = tmp_path / "in.json"
    src.write_bytes(content)
    before = snapshot(tmp_path)
    argv = [verb, str(src), "--json", str(tmp_path / "o.json")]
    cli_error(capsys, argv + (["--out", str(tmp_path / "r")] if verb == "report" else []),
              fragment)
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("doc,fragment", [
    ({}, "not a model JSON"),
    ({"terms": 3}, "not a model JSON"),
    ({"terms": [1, 2]}, ""),
    ({"terms": [{"name": "u(k-1)", "estimate": "x"}]}, ""),
    ({"last_model": [1]}, "not a model JSON"),
    # JSON true or a quoted number is not a number (true was once read as 1.0)
    ({"terms": [{"name": "u(k-1)", "estimate": True}], "sample_rate_hz": 500},
     "term u(k-1): estimate must be a number, got true"),
    ({"terms": [{"name": "u(k-1)", "estimate": "0.5"}], "sample_rate_hz": 500},
     'term u(k-1): estimate must be a number, got "0.5"'),
    ({"terms": [{"name": "u(k-1)", "estimate": 0.5}], "sample_rate_hz": True},
     "sample_rate_hz must be a number, got true"),
    ({"terms": [{"name": "u(k-1)", "estimate": 0.5}], "sample_rate_hz": 500,
      "structure": {"ny": 1, "nu": True, "degree": 1}}, "structure nu must be a whole number"),
])
def test_json_of_the_wrong_kind_for_gfrf(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         doc: object, fragment: str) -> None:
    src = tmp_path / "m.json"
    src.write_text(json.dumps(doc))
    cli_error(capsys, ["gfrf", str(src)], str(src), fragment)


def test_json_of_the_wrong_kind_for_report(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "x.json"
    src.write_text('{"hello": 1}')
    cli_error(capsys, ["report", str(src), "--out", str(tmp_path / "r")],
              "not a result JSON of identify, gfrf, diagnose or run --json")
    assert not (tmp_path / "r").exists()


def test_a_directory_given_as_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cli_error(capsys, ["gfrf", str(tmp_path)], "is a directory")


# ----------------------------------------------------------------------------- import-mat


def test_import_mat_refuses_complex_missing_and_foreign_files(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    t = np.arange(10) / 1000.0
    good = {"t": t, "qm": t, "vir": np.ones(10), "gtau": 1.0}
    cases = {
        "complex.mat": ({**good, "vir": np.ones(10) + 1j}, "'vir' holds complex numbers"),
        "missing.mat": ({"t": t}, "missing key(s) qm, vir, gtau"),
        "text.mat": ({**good, "qm": np.array(["abc"])}, "'qm' is not numeric"),
        # once "only 0 samples align": the gain itself is named
        "inf_gain.mat": ({**good, "gtau": np.inf}, "'gtau' is not finite (inf)"),
    }
    for name, (d, fragment) in cases.items():
        scipy.io.savemat(tmp_path / name, d)
        cli_error(capsys, ["import-mat", str(tmp_path / name), "--out", str(tmp_path / "o")],
                  fragment)
    (tmp_path / "notes.mat").write_text("not a mat file\n")
    cli_error(capsys, ["import-mat", str(tmp_path / "notes.mat"), "--out", str(tmp_path / "o")],
              "not a readable MATLAB .mat file")
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- recordings


@pytest.fixture(scope="module")
def clean_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    u, y = known_data()
    return bag_of(tmp_path_factory.mktemp("bags") / "clean", u, y)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_zero_byte_storage(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                           storage: str) -> None:
    bag = tmp_path / "b"
    assert main(["simulate", "--duration", "1", "--out", str(bag), "--storage", storage]) == 0
    for f in bag.glob("*.mcap" if storage == "mcap" else "*.db3"):
        f.write_bytes(b"")
    capsys.readouterr()
    cli_error(capsys, ["identify", str(bag), *SMALL], "is empty (0 bytes)")


def test_garbage_metadata_and_too_few_samples(tmp_path: Path, clean_bag: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    bag = tmp_path / "garbage"
    shutil.copytree(clean_bag, bag)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: 5\n")
    cli_error(capsys, ["identify", str(bag), *SMALL], "corrupt metadata.yaml")
    (bag / "metadata.yaml").write_bytes(b"\x00\xff" * 100)
    cli_error(capsys, ["identify", str(bag), *SMALL], str(bag))
    u, y = known_data(12)
    short = bag_of(tmp_path / "short", u, y)
    cli_error(capsys, ["identify", str(short), *SMALL, "--estimate", "0:12", "--no-validate"],
              "samples are too few")
