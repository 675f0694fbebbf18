"""The public Python API (``import pmsm_sysid as ps``): each result's ``to_dict()`` is the JSON
the matching verb writes, options are checked before any work, the import stays light, and
every public name carries a docstring with an example that runs."""

from __future__ import annotations

import doctest
import json
import runpy
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pmsm_sysid as ps
from pmsm_sysid.cli import main

REPO = Path(__file__).resolve().parents[1]
NOMINAL = REPO / "bags" / "paper_speed_nominal"
COULOMB = REPO / "bags" / "paper_speed_coulomb"
#: run-time measurements differ between any two runs; everything else must be equal
TIMING = {"timing_ms"}


def _drop_timing(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _drop_timing(v) for k, v in d.items() if k not in TIMING}
    if isinstance(d, list):
        return [_drop_timing(v) for v in d]
    return d


def _cli_json(tmp_path: Path, name: str, *argv: str) -> dict[str, Any]:
    out = tmp_path / f"{name}.json"
    assert main([*argv, "--json", str(out)]) == 0
    loaded: dict[str, Any] = json.loads(out.read_text())
    return loaded


def test_identify_to_dict_is_the_cli_json(tmp_path: Path) -> None:
    cli = _cli_json(tmp_path, "identify", "identify", str(NOMINAL), "--terms", "8",
                    "--criterion", "bic", "--estimate", "500:2000", "--validate", "2500:4000",
                    "--method", "ofr")
    api = ps.identify(NOMINAL, terms=8, criterion="bic", estimate=(500, 2000),
                      validate=(2500, 4000), method="ofr")
    assert isinstance(api, ps.Identification)
    assert _drop_timing(api.to_dict()) == _drop_timing(cli)
    assert set(cli["timing_ms"]) == set(api.to_dict()["timing_ms"])
    assert cli["source"] == str(NOMINAL.resolve()) and "alignment" in cli


def test_identify_of_a_recording_equals_identify_of_its_bag() -> None:
    rec = ps.read_bag(NOMINAL)
    from_rec, from_bag = ps.identify(rec, validate=None), ps.identify(NOMINAL, validate=None)
    a, b = _drop_timing(from_rec.to_dict()), _drop_timing(from_bag.to_dict())
    assert "source" not in a and "alignment" not in a
    del b["source"], b["alignment"]
    assert a == b


def test_gfrf_to_dict_is_the_cli_json(tmp_path: Path) -> None:
    model = _cli_json(tmp_path, "model", "identify", str(NOMINAL))
    cli = _cli_json(tmp_path, "gfrf", "gfrf", str(tmp_path / "model.json"),
                    "--at", "0.033", "--at", "0.033,0.033", "--grid", "8", "--orders", "1,2")
    fit = ps.identify(NOMINAL)
    api = ps.gfrf(fit, at=[(0.033,), (0.033, 0.033)], grid=8, orders=(1, 2))
    assert isinstance(api, ps.GfrfAnalysis)
    assert _drop_timing(api.to_dict()) == _drop_timing(cli)
    # the identify JSON (a dict or its file) gives the same analysis as the result object
    for model_arg in (model, tmp_path / "model.json"):
        again = ps.gfrf(model_arg, at=[(0.033,), (0.033, 0.033)], grid=8, orders=(1, 2))
        assert _drop_timing(again.to_dict()) == _drop_timing(cli)


@pytest.mark.slow
def test_diagnose_to_dict_is_the_cli_json(tmp_path: Path) -> None:
    plant = REPO / "plants" / "nominal.yaml"
    cli = _cli_json(tmp_path, "diagnose", "diagnose", "--plant", str(plant), "--real",
                    str(COULOMB), "--no-gfrf", "--alpha", "0.01")
    api = ps.diagnose(str(plant), str(COULOMB), gfrf=False, alpha=0.01)
    assert isinstance(api, ps.Diagnosis)
    assert _drop_timing(api.to_dict()) == _drop_timing(cli)
    assert [e["name"] for e in cli["effects"]] == ["coulomb_friction"]
    # objects instead of files: the same diagnosis, without the file names
    objects = ps.diagnose(ps.Plant.from_yaml(plant), ps.read_bag(COULOMB), gfrf=False,
                          alpha=0.01).to_dict()
    assert "plant_file" not in objects and "real" not in objects
    assert objects["effects"] == cli["effects"]


def test_simulate_equals_the_bag_the_cli_writes(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", "--plant", str(REPO / "plants" / "nominal_noisy.yaml"),
                 "--excitation", "multisine", "--duration", "2", "--seed", "4",
                 "--amplitude", "30", "--excitation-option", "f_max_hz=60",
                 "--out", str(out)]) == 0
    rec = ps.simulate(REPO / "plants" / "nominal_noisy.yaml", excitation="multisine",
                      duration=2.0, seed=4, amplitude=30.0,
                      excitation_options={"f_max_hz": 60})
    back = ps.read_bag(out)
    assert isinstance(rec, ps.Recording) and len(rec) == len(back) == 1000
    for name in ("t", "thrust", "speed", "position"):
        np.testing.assert_allclose(getattr(back, name), getattr(rec, name), rtol=0, atol=1e-9)
    written = ps.write_bag(rec, tmp_path / "api_sim")
    assert {k: v for k, v in ps.read_bag(written).meta.items() if k != "bag"} == \
        {k: v for k, v in back.meta.items() if k != "bag"}


def test_simulate_plant_forms_agree() -> None:
    by_default = ps.simulate(duration=1.0, seed=2)
    for plant in (ps.Plant.nominal(), ps.Plant.from_yaml(REPO / "plants" / "nominal.yaml"),
                  str(REPO / "plants" / "nominal.yaml")):
        np.testing.assert_array_equal(ps.simulate(plant, duration=1.0, seed=2).speed,
                                      by_default.speed)


def test_write_bag_refuses_to_overwrite_unless_asked(tmp_path: Path) -> None:
    rec = ps.simulate(duration=0.5)
    path = ps.write_bag(rec, tmp_path / "b")
    with pytest.raises(ps.PmsmSysidError, match="exists already"):
        ps.write_bag(rec, path)
    ps.write_bag(rec, path, overwrite=True, storage="sqlite3")
    assert len(ps.read_bag(path)) == len(rec)
    (tmp_path / "plain").mkdir()
    with pytest.raises(ps.PmsmSysidError, match="not a rosbag2 directory"):
        ps.write_bag(rec, tmp_path / "plain", overwrite=True)


@pytest.mark.parametrize(("call", "fragment"), [
    (lambda: ps.identify("no/such/bag", terms=0), "terms must be at least 1"),
    (lambda: ps.identify("no/such/bag", estimate=(10, 5)), "estimate needs 0 <= start < stop"),
    (lambda: ps.identify("no/such/bag", method="ls"), "method must be one of"),
    (lambda: ps.identify("no/such/bag", output="current"), "output must be one of"),
    (lambda: ps.identify("no/such/bag", rho=1.5), "rho must be a number in (0, 1)"),
    (lambda: ps.identify("no/such/bag", ny=True), "ny must be an integer"),
    (lambda: ps.identify(42), "data must be a Recording or a bag path"),
    (lambda: ps.gfrf({"terms": []}, at=[(0.7,)]), "within [-0.5, 0.5]"),
    (lambda: ps.gfrf({"terms": []}, grid=1), "grid must be"),
    (lambda: ps.gfrf({"terms": []}, orders=(4,)), "orders are among 1, 2, 3"),
    (lambda: ps.gfrf({"no": "terms"}), "not a model JSON"),
    (lambda: ps.diagnose(None, "no/such/bag", alpha=0), "alpha must be a number in (0, 1)"),
    (lambda: ps.diagnose(3, "no/such/bag"), "plant must be None, a Plant or"),
    (lambda: ps.simulate(duration=-1), "duration must be a positive"),
    (lambda: ps.simulate(excitation="square"), "excitation must be one of"),
    (lambda: ps.simulate("no/such/plant.yaml"), "no such plant file"),
    (lambda: ps.write_bag("not a recording", "x"), "write_bag needs a Recording"),
])
def test_bad_options_raise_the_base_error_before_any_work(call: Any, fragment: str) -> None:
    """The bag path does not exist: a bad option is reported before the data are read."""
    with pytest.raises(ps.PmsmSysidError) as info:
        call()
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_import_is_light_and_offline_verbs_load_no_ros_and_no_plotting(tmp_path: Path) -> None:
    """Each public name loads its own module on first use: identify, gfrf and simulate load
    neither ROS nor plotting nor what a diagnosis needs, and neither does what the live
    workers' fork server preloads."""
    code = (
        "import sys, pmsm_sysid as ps\n"
        "heavy = ('numpy', 'scipy', 'rclpy', 'matplotlib', 'rosbags')\n"
        "assert not [m for m in heavy if m in sys.modules], sys.modules.keys()\n"
        "assert sorted(ps.__all__) == sorted(set(ps.__all__))\n"
        "from pmsm_sysid.cli import main\n"
        f"assert main(['identify', {str(NOMINAL)!r}, '--terms', '5']) == 0\n"
        f"assert main(['gfrf', {str(REPO / 'test' / 'missing.json')!r}]) == 2\n"
        "assert main(['simulate', '--duration', '1', '--out', "
        f"{str(tmp_path / 'sim')!r}]) == 0\n"
        "loaded = [m for m in ('rclpy', 'matplotlib') if m in sys.modules]\n"
        "assert not loaded, loaded\n"
        # nor what the live workers' fork server preloads
        "from pmsm_sysid.core.online.workerproc import PRELOAD\n"
        "for m in PRELOAD: __import__(m)\n"
        # what a diagnosis needs, not an identification (about half a second of CPU)
        "loaded = [m for m in ('scipy.signal', 'scipy.stats', 'scipy.optimize', "
        "'pmsm_sysid.api.diagnosis', 'pmsm_sysid.core.discrepancy') if m in sys.modules]\n"
        "assert not loaded, loaded\n"
        "assert ps.diagnose.__module__ == 'pmsm_sysid.api.diagnosis'\n"
        "assert 'scipy.signal' in sys.modules\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, timeout=300)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slow
def test_every_public_name_is_documented_with_an_example_that_runs(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)  # the examples read the bundled bags by relative path
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for name in ps.__all__:
        obj = getattr(ps, name)
        assert obj.__doc__ and "Example" in obj.__doc__, f"{name}: no docstring example"
        for test in finder.find(obj, name):
            runner.run(test)
    for test in finder.find(ps, "pmsm_sysid"):
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted >= 40, result


def test_public_functions_are_typed() -> None:
    import inspect
    import typing

    for name in ps.__all__:
        obj = getattr(ps, name)
        if inspect.isfunction(obj):
            hints = typing.get_type_hints(obj)
            params = set(inspect.signature(obj).parameters)
            assert params <= set(hints) and "return" in hints, name


def test_api_reference_builds_from_the_docstrings(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """``make docs``: pdoc renders one page with every public name and its example (the
    script run as ``__main__`` in this process: the modules it documents are loaded here
    already)."""
    script = REPO / "scripts" / "api_docs.py"
    monkeypatch.chdir(REPO)
    monkeypatch.setattr(sys, "argv", [str(script), str(tmp_path / "api")])
    runpy.run_path(str(script), run_name="__main__")
    assert f"API reference: {tmp_path / 'api' / 'pmsm_sysid.html'}" in capsys.readouterr().out
    page = (tmp_path / "api" / "pmsm_sysid.html").read_text()
    for name in ps.__all__:
        assert f'id="{name}"' in page, name
    assert page.count("Example") >= len(ps.__all__)
