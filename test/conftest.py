"""Shared fixtures. The ROS fixtures (``ros_env``, ``ros_context``, ``ros_executor``,
``sim_motor``: a private domain id, log dir and rclpy Context per test) come from the
package's own pytest plugin, :mod:`pmsm_sysid.testing.pytest_plugin`, which installing the
package registers with pytest; a source checkout that is not installed loads it here.

``chromium`` (session): headless Chromium as the set-up (``make browser``, part of ``make
test``) left it -- ``chromium.run(url, profile_dir, *flags)`` starts it offline, with the
flags it needs on this machine. Where the set-up could not install it (not root, no
apt-get) the test is skipped with that reason; where it promised a browser and there is
none, the test fails.

``--without-ros`` (what ``make check`` runs) deselects the tests marked ``ros`` and makes
rclpy and the ROS message packages unimportable, in the test process and in every Python
process a test starts, as on a plain ``pip install`` without the ``[ros]`` extra: a test
that needs ROS and is not marked ``ros`` fails there.
"""

from __future__ import annotations

import gc
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

from pmsm_sysid.dds import use_packaged_profile

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
EMPS_MAT = SHARED / "data" / "emps" / "DATA_EMPS.mat"
PLUGIN = "pmsm_sysid.testing.pytest_plugin"
#: What a plain install (no ``[ros]`` extra, no sourced ROS) cannot import.
ROS_MODULES = ("rclpy", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs",
               "rosgraph_msgs", "builtin_interfaces", "rcl_interfaces")
#: What ``make browser`` (scripts/install_browser.sh) promised: "chromium PATH", "none
#: REASON" or "failed REASON".
BROWSER_STATE = REPO / ".venv" / ".browser"
CHROMIUM_NAMES = ("chromium", "chromium-browser")
_BLOCK = '''import sys


class _WithoutRos:
    """Import finder: the ROS modules are not installed (pytest --without-ros)."""

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {names!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}} (--without-ros)", name=name)
        return None


sys.meta_path.insert(0, _WithoutRos())
'''

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# the package's Fast DDS profile (pmsm_sysid.dds) in every test process and the processes
# they start, before any test initialises rclpy (Fast DDS reads profiles once per process):
# the tests that init a Context of their own run with the writers the product runs with
use_packaged_profile()


UNGROUPED = pytest.StashKey[bool]()
#: Multiprocessing starts one fork server per process, and all its users share it: in a
#: test process, the live pipeline's fit and GFRF workers, the diagnosis worker, the
#: recorder process and a fleet's local workers (Dask's ``forkserver`` method). Whoever
#: started it first chose what it imports (a fleet's cluster: Dask's list), and every
#: process forked for the others imported the rest itself, about a second of CPU each. So
#: each test process starts it before its first test, preloading what they all need: the
#: live workers' :data:`~pmsm_sysid.core.online.workerproc.PRELOAD`, these, and a fleet
#: row's :data:`~pmsm_sysid.api.fleet_row.ROW_MODULES` (an import that fails, e.g. rclpy
#: under ``--without-ros``, is skipped by the server).
FORK_SERVER_USERS = ("pmsm_sysid.core.frequency.message", "pmsm_sysid.nodes.diagnosis_work",
                     "pmsm_sysid.nodes.recorder_process")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--without-ros", action="store_true",
                     help="run as without ROS: deselect the 'ros' tests; rclpy and the ROS "
                          "message packages cannot be imported here or in subprocesses")
    parser.addoption("--cpu-report", metavar="FILE", default=None,
                     help="append one JSON line per test to FILE: its CPU seconds (user + "
                          "sys of the test process and of the processes it started and "
                          "waited for, set-up and teardown included) and wall seconds")


def pytest_configure(config: pytest.Config) -> None:
    """Load the plugin unless its entry point already did (never register it twice)."""
    import importlib

    if config.getoption("--without-ros"):
        _block_ros()
    manager = config.pluginmanager
    if manager.is_registered(importlib.import_module(PLUGIN)):
        return
    manager.register(importlib.import_module(PLUGIN), "pmsm_sysid")


def pytest_unconfigure(config: pytest.Config) -> None:
    site = os.environ.get("PMSM_SYSID_WITHOUT_ROS")
    if site and "PYTEST_XDIST_WORKER" not in os.environ:  # made by this (controller) process
        shutil.rmtree(site, ignore_errors=True)


def _block_ros() -> None:
    """ROS modules unimportable in this process and (via a ``sitecustomize`` on
    PYTHONPATH) in every Python process started from it."""
    loaded = [m for m in sys.modules if m.split(".")[0] in ROS_MODULES]
    assert not loaded, f"--without-ros: ROS modules already imported: {loaded}"
    code = _BLOCK.format(names=ROS_MODULES)
    exec(compile(code, "<without-ros>", "exec"), {"__name__": "pmsm_sysid_without_ros"})
    if "PMSM_SYSID_WITHOUT_ROS" in os.environ:
        return  # an xdist worker: the controller has set PYTHONPATH already
    site = Path(tempfile.mkdtemp(prefix="pmsm_sysid_without_ros_"))
    (site / "sitecustomize.py").write_text(code)
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(site), *filter(None, [os.environ.get("PYTHONPATH")])])
    os.environ["PMSM_SYSID_WITHOUT_ROS"] = str(site)


@pytest.hookimpl(trylast=True)  # after pytest-xdist has named each test's group
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Modules with ``slow`` tests first, each module's tests kept together (module fixtures
    are made once) and in order, so that the test processes get the long tests early
    and finish together; with ``--without-ros``, the ``ros`` tests are deselected. Under
    ``--dist loadgroup`` a test of an ``xdist_group`` that did not get its group (a pytest
    that pytest-xdist cannot group with) fails: the group's shared runs would be made once
    in each test process."""
    if getattr(config.option, "loadgroup", False):
        for item in items:
            if item.get_closest_marker("xdist_group") and "@" not in item.nodeid:
                item.stash[UNGROUPED] = True
    if config.getoption("--without-ros"):
        ros = [item for item in items if item.get_closest_marker("ros")]
        if ros:
            config.hook.pytest_deselected(items=ros)
            items[:] = [item for item in items if not item.get_closest_marker("ros")]
    slow_modules = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_modules)  # stable: order otherwise kept


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session: pytest.Session) -> None:
    """Before the first test of a test process: what collection made (the modules, every
    test item: most of the process's objects) out of the cyclic garbage collector's sight
    (``gc.freeze``), so that its full collections walk only what the tests made. Measured
    on the suite: the three test processes' time in the collector 10.3 -> 5.5 s of CPU.
    Then the process's fork server is started (:data:`FORK_SERVER_USERS`)."""
    gc.collect()
    gc.freeze()
    config = session.config
    runs_tests = hasattr(config, "workerinput") or not config.getoption("numprocesses", None)
    if runs_tests and not config.option.collectonly:  # not pytest-xdist's controller
        _start_fork_server()


def _start_fork_server() -> None:
    """Start this test process's fork server, preloading what its users need
    (:data:`FORK_SERVER_USERS`)."""
    from pmsm_sysid.api.fleet_row import ROW_MODULES
    from pmsm_sysid.core.online.workerproc import PRELOAD, start_server

    start_server([*PRELOAD, *FORK_SERVER_USERS, "distributed", *ROW_MODULES])


def _cpu_now() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> object:
    """With ``--cpu-report FILE``: each test's CPU (a module or session fixture's set-up
    counts in the first test that uses it) and wall time, one JSON line per test."""
    target = item.config.getoption("--cpu-report")
    if not target:
        yield
        return
    import time

    cpu, wall = _cpu_now(), time.monotonic()
    yield
    line = {"test": item.nodeid, "cpu_s": round(_cpu_now() - cpu, 3),
            "wall_s": round(time.monotonic() - wall, 3),
            "worker": os.environ.get("PYTEST_XDIST_WORKER", "main")}
    with open(target, "a", encoding="utf-8") as out:
        out.write(json.dumps(line) + "\n")


def pytest_runtest_setup(item: pytest.Item) -> None:
    """A test that ``--dist loadgroup`` left without its group fails."""
    if item.stash.get(UNGROUPED, False):
        pytest.fail(f"--dist loadgroup did not put this test in its group (pytest "
                    f"{pytest.__version__} with this pytest-xdist; install requirements.lock)",
                    pytrace=False)


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared beside the repo; a test that needs it fails (not skips) if it is missing."""
    assert SHARED.is_dir(), f"../shared not found at {SHARED}"
    return SHARED


@dataclass(frozen=True)
class EmpsDiagnosis:
    """The EMPS recording as ``import-mat`` writes it, and ``diagnose`` of the whole of it
    against plants/emps.yaml (``--json``, ``--report``): each command's result as
    :func:`cli_inprocess.invoke` gives it (exit status, stdout, stderr)."""

    imported: subprocess.CompletedProcess[str]
    bag: Path
    diagnosed: subprocess.CompletedProcess[str]
    json: Path
    report: Path


@pytest.fixture(scope="session")
def emps_diagnosis(tmp_path_factory: pytest.TempPathFactory) -> EmpsDiagnosis:
    """The EMPS import and its diagnosis, made once for the tests that read them (the real
    recording's numbers, and the walkthrough that replays a slice of it): the same command
    on the same bag gives the same JSON (its timings apart), and it costs about 1.5 s of
    CPU, plus a Python and its imports where it ran as a process. The tests that use it
    share ``xdist_group("emps")``, so that under ``--dist loadgroup`` it is made in one test
    process only. The bag and the files are only read."""
    from cli_inprocess import invoke

    assert EMPS_MAT.is_file(), f"{EMPS_MAT} missing"
    tmp = tmp_path_factory.mktemp("emps")
    bag, out, rep = tmp / "emps", tmp / "emps.json", tmp / "rep"
    imported = invoke("import-mat", str(EMPS_MAT), "--out", str(bag))
    diagnosed = invoke("diagnose", "--plant", str(REPO / "plants" / "emps.yaml"), "--real",
                       str(bag), "--json", str(out), "--report", str(rep))
    return EmpsDiagnosis(imported, bag, diagnosed, out, rep)


@dataclass(frozen=True)
class Chromium:
    """A headless Chromium binary and how to start it here (as root, offline)."""

    path: str

    def run(self, url: str, profile: Path, *flags: str,
            timeout: float = 180.0) -> subprocess.CompletedProcess[str]:
        """Load ``url`` headless with a fresh profile in ``profile`` and no network (every
        host name unresolvable, a dead proxy); ``flags`` add e.g. ``--dump-dom`` or
        ``--screenshot=FILE``."""
        args = [self.path, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
                "--hide-scrollbars", "--force-device-scale-factor=1",
                "--virtual-time-budget=10000", "--host-resolver-rules=MAP * ~NOTFOUND",
                "--proxy-server=127.0.0.1:9", *flags, url]
        return subprocess.run(args, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="session")
def chromium() -> Chromium:
    """Headless Chromium from the set-up (see the module doc); never installs anything."""
    found = next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)
    state = BROWSER_STATE.read_text().strip() if BROWSER_STATE.is_file() else ""
    kind, _, detail = state.partition(" ")
    if found:
        return Chromium(found)
    if kind == "chromium":
        pytest.fail(f"the set-up installed chromium ({detail}) but it is not on PATH now",
                    pytrace=False)
    if kind == "failed":
        pytest.fail(f"the set-up could not install chromium: {detail}", pytrace=False)
    if kind == "none":
        pytest.skip(f"NO BROWSER: {detail} (make browser)")
    pytest.skip("NO BROWSER: chromium is not installed; `make browser` (part of `make test`) "
                "installs it")

