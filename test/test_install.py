"""Installs with and without ROS: a plain install runs every offline verb; a live verb
without rclpy exits 2 with one line naming the ``[ros]`` extra, before any work."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

WITHOUT_ROS = """
import sys
for name in ("rclpy", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs",
             "rosgraph_msgs", "builtin_interfaces", "rcl_interfaces"):
    sys.modules[name] = None  # as on a plain 'pip install' without the [ros] extra
from pmsm_sysid.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _without_ros(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", WITHOUT_ROS, *argv], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


@pytest.mark.parametrize("argv", [
    ["run", "--duration", "1"], ["record", "--out", "never_written"],
    ["replay", str(REPO / "bags" / "paper_speed_nominal")], ["monitor", "--once"],
])
def test_live_verb_without_rclpy_is_one_line_naming_the_extra(argv: list[str],
                                                             tmp_path: Path) -> None:
    proc = _without_ros(*argv, cwd=tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"pmsm-sysid {argv[0]}: error:")
    assert "pip install 'pmsm_sysid[ros]'" in lines[0] and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []  # refused before any work


#: The offline verbs one after the other in one Python without ROS (each its own
#: ``main``): numpy, scipy and matplotlib are imported once, not once per verb; the first
#: verb that fails stops it with its argv and its exit status on stderr.
OFFLINE_STEPS = WITHOUT_ROS.replace("sys.exit(main(sys.argv[1:]))", """
import json
for argv in json.loads(sys.argv[1]):
    code = main(argv)
    if code != 0:
        sys.stderr.write(f"{argv}: exit {code}\\n")
        sys.exit(code)
""")


@pytest.mark.slow
def test_offline_verbs_run_without_rclpy(tmp_path: Path) -> None:
    bag = str(REPO / "bags" / "paper_speed_nominal")
    steps = [
        ["simulate", "--duration", "1", "--out", "sim"],
        ["identify", bag, "--json", "id.json"],
        ["gfrf", "id.json", "--json", "g.json"],
        ["diagnose", "--plant", str(REPO / "plants" / "nominal.yaml"), "--real",
         str(REPO / "bags" / "paper_speed_coulomb"), "--no-gfrf", "--json", "d.json"],
        ["report", "id.json", "--out", "rep"],
    ]
    proc = subprocess.run([sys.executable, "-c", OFFLINE_STEPS, json.dumps(steps)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    for made in ("sim/metadata.yaml", "id.json", "g.json", "d.json", "rep/index.html"):
        assert (tmp_path / made).is_file(), made


def test_base_install_has_no_ros_and_the_ros_extra_has_the_locked_wheels(
        tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "setup.py", "-q", "egg_info", "--egg-base",
                           str(tmp_path)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    requires = (tmp_path / "pmsm_sysid.egg-info" / "requires.txt").read_text()
    sections: dict[str, list[str]] = {"": []}
    current = ""
    for line in filter(None, requires.splitlines()):
        if line.startswith("["):
            current = line.strip("[]")
            sections[current] = []
        else:
            sections[current].append(line)
    base = sections[""]
    assert not [r for r in base if r.lower().startswith(("ros-", "rclpy"))], base
    assert {"numpy", "scipy", "matplotlib", "PyYAML"} <= {r.split(">")[0] for r in base}
    lock = {line.split("==")[0] for line in (REPO / "requirements.lock").read_text().split()}
    ros = [r.split("~=")[0] for r in sections["ros"]]
    assert ros and all(name.startswith("ros-jazzy-") and name in lock for name in ros), ros
    # fleet: Dask distributed and pyarrow, in the extra, not in the base install
    assert set(sections["fleet"]) == {"dask[distributed]", "pyarrow"}
    assert {"dask[distributed]", "pyarrow"} <= set(sections["test"])
    assert not [r for r in base if r.split("[")[0] in ("dask", "distributed", "pyarrow")]


def test_the_fleet_extra_and_everything_it_needs_is_pinned_in_the_lock() -> None:
    """Every distribution dask[distributed] and pyarrow pull in on this Python (as installed
    here, from the lock) is pinned in requirements.lock with the version installed: a fresh
    ``make venv`` brings the same ones."""
    from importlib import metadata

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    lock = {canonicalize_name(k): v for k, v in (
        line.split("==") for line in (REPO / "requirements.lock").read_text().split())}
    todo, seen = [("dask", "distributed"), ("distributed", ""), ("pyarrow", "")], set()
    while todo:
        name, extra = todo.pop()
        if (name, extra) in seen:
            continue
        seen.add((name, extra))
        dist = metadata.distribution(name)
        assert lock.get(canonicalize_name(name)) == dist.version, (name, dist.version)
        for text in dist.requires or []:
            req = Requirement(text)
            if req.marker is None or req.marker.evaluate({"extra": extra}):
                todo += [(canonicalize_name(req.name), e) for e in (req.extras or {""})]
    names = {n for n, _ in seen}
    assert {"dask", "distributed", "pyarrow", "tornado", "cloudpickle", "msgpack",
            "importlib-metadata"} <= names, names


EXECUTABLES = ("diagnose", "gfrf", "identifier", "pmsm-sysid", "sim")


def test_the_venvs_editable_install_puts_the_executables_on_its_path() -> None:
    """``make venv`` (an editable install, built through pyproject.toml): the console
    scripts are in the environment's bin/, not in the ROS directory setup.cfg names for
    colcon."""
    bin_dir = Path(sys.executable).parent
    assert all((bin_dir / name).is_file() for name in EXECUTABLES)
    assert not (Path(sys.prefix) / "lib" / "pmsm_sysid").exists()


def test_pip_install_puts_the_executables_in_bin(tmp_path: Path) -> None:
    """``pip install .`` builds a wheel: the console scripts go to the prefix's bin/ (where a
    pip user's PATH looks), whatever setup.cfg sets for colcon's lib/pmsm_sysid."""
    import shutil

    src = tmp_path / "src"  # a copy: a wheel build writes build/ beside setup.py
    src.mkdir()
    for name in ("setup.py", "setup.cfg", "pyproject.toml", "package.xml"):
        shutil.copy2(REPO / name, src / name)
    for name in ("pmsm_sysid", "resource", "msg_schemas"):
        shutil.copytree(REPO / name, src / name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check"]
    built = subprocess.run([*pip, "wheel", "-q", "--no-deps", "--no-build-isolation",
                            "-w", str(tmp_path / "dist"), str(src)],
                           capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr
    wheel = next((tmp_path / "dist").glob("pmsm_sysid-*.whl"))
    prefix = tmp_path / "prefix"
    # --ignore-installed: never uninstall this environment's own copy on the way
    done = subprocess.run([*pip, "install", "-q", "--no-deps", "--no-index", "--ignore-installed",
                           "--prefix", str(prefix), str(wheel)], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (prefix / "bin").iterdir()) == sorted(EXECUTABLES)
    assert not (prefix / "lib" / "pmsm_sysid").exists()
    assert (prefix / "share" / "pmsm_sysid" / "package.xml").is_file()
