"""``colcon build`` of the repository as an ament_python package, in a workspace of its own:
package.xml, the ament index marker and the message schemas land under share/, the
ament index finds the package, the installed copy runs from the install space, and the
executables are where ``ros2 run`` and launch files look (``lib/pmsm_sysid/``): the tool
``pmsm-sysid`` and one executable per node, which compose the pipeline node by node with
``--ros-args`` (namespace, params file, parameters), as a user's launch file does. (There is
no ``ros2`` command here: the install tree is checked directly, with its own environment.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
EXECUTABLES = ("diagnose", "gfrf", "identifier", "pmsm-sysid", "sim")

CHECK = """
import json, sys
from ament_index_python.packages import get_package_prefix, get_package_share_directory
import pmsm_sysid, pmsm_sysid.bagio as bagio
print(json.dumps({"share": get_package_share_directory("pmsm_sysid"),
                  "prefix": get_package_prefix("pmsm_sysid"), "module": pmsm_sysid.__file__,
                  "schemas": str(bagio.schema_dir()),
                  "types": sorted(t for t in bagio.typestore().fielddefs
                                  if t.startswith("pmsm_sysid/"))}))
"""


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A colcon workspace with this checkout in src/, built and installed."""
    ws = tmp_path_factory.mktemp("colcon") / "ws"
    (ws / "src").mkdir(parents=True)
    (ws / "src" / "pmsm_sysid").symlink_to(REPO)
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("PYTHONPATH", None)
    proc = subprocess.run(
        [str(BIN / "colcon"), "--log-base", str(ws / "log"), "build", "--base-paths", "src",
         "--build-base", str(ws / "build"), "--install-base", str(ws / "install"),
         "--event-handlers", "console_direct-"],
        cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Finished <<< pmsm_sysid" in proc.stdout, proc.stdout
    return ws


def _installed(ws: Path, command: str, *args: str, **popen: Any) -> subprocess.Popen[str]:
    """``lib/pmsm_sysid/<command> args`` run as ``ros2 run`` would, in the install's
    environment (``install/setup.sh`` sourced)."""
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("PYTHONPATH", None)
    exe = ws / "install" / "pmsm_sysid" / "lib" / "pmsm_sysid" / command
    script = f'. "{ws / "install" / "setup.sh"}" && exec "$0" "$@"'
    return subprocess.Popen(["sh", "-c", script, str(exe), *args], env=env, text=True,
                            cwd=ws, **popen)


def test_colcon_build_installs_an_ament_python_package(workspace: Path,
                                                       tmp_path: Path) -> None:
    ws = workspace
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("PYTHONPATH", None)
    prefix = ws / "install" / "pmsm_sysid"
    share = prefix / "share" / "pmsm_sysid"
    assert (share / "package.xml").read_text() == (REPO / "package.xml").read_text()
    assert sorted(p.name for p in (share / "msg_schemas").glob("*.msg")) == \
        sorted(p.name for p in (REPO / "msg_schemas").glob("*.msg"))
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" /
            "pmsm_sysid").is_file()
    # the executables are where ros2 run and launch files look, and only there
    lib = prefix / "lib" / "pmsm_sysid"
    assert sorted(p.name for p in lib.iterdir()) == sorted(EXECUTABLES)
    assert all(os.access(lib / name, os.X_OK) for name in EXECUTABLES)
    assert not (prefix / "bin").exists()
    site = next(prefix.glob("lib/python3*/site-packages"))
    # the ament index finds it; the installed copy (not this checkout) is imported and
    # reads its message schemas from the install space
    check_env = {**env, "AMENT_PREFIX_PATH": str(prefix), "PYTHONPATH": str(site)}
    run = subprocess.run([sys.executable, "-c", CHECK], cwd=tmp_path, env=check_env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout)
    assert Path(got["share"]) == share and Path(got["prefix"]) == prefix
    assert Path(got["module"]).is_relative_to(site)
    assert Path(got["schemas"]) == share / "msg_schemas"
    assert "pmsm_sysid/msg/NarxModel" in got["types"]
    # `ros2 run pmsm_sysid pmsm-sysid --help` and a node executable's --help
    for command, expect in (("pmsm-sysid", "identify"), ("identifier", "--ros-args")):
        proc = _installed(ws, command, "--help", stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE)
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0 and expect in out, (command, out, err)


@pytest.fixture
def started(workspace: Path) -> Iterator[dict[str, subprocess.Popen[str]]]:
    """Node executables started from the install tree; none left running after the test."""
    procs: dict[str, subprocess.Popen[str]] = {}
    yield procs
    for p in procs.values():
        if p.poll() is None:
            p.kill()
            p.communicate(timeout=60)


@pytest.mark.ros
def test_node_executables_compose_the_pipeline_with_ros_args(
        workspace: Path, tmp_path: Path, ros_context: Any, ros_executor: Any,
        started: dict[str, subprocess.Popen[str]]) -> None:
    """``sim``, ``identifier`` and ``gfrf`` each start their node alone; with ``-r __ns:=/x``
    they form the pipeline in ``/x`` (samples, models, ridges there), a params file keyed by
    the bare node name and a ``-p`` reach the identifier, and SIGINT/SIGTERM end each
    cleanly."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.node import Node
    from std_msgs.msg import String

    from pmsm_sysid.rosutil import data_qos
    from pmsm_sysid.testing import spin_until

    ns = f"/x{uuid.uuid4().hex[:8]}"
    params = tmp_path / "params.yaml"
    params.write_text("pmsm_identifier:\n  ros__parameters:\n    outputs: [speed]\n")
    probe = Node("probe", context=ros_context)
    got: dict[str, list[Any]] = {"thrust": [], "model": [], "ridges": []}
    probe.create_subscription(WrenchStamped, f"{ns}/thrust", got["thrust"].append, data_qos())
    for topic in ("model", "ridges"):
        probe.create_subscription(String, f"{ns}/{topic}",
                                  lambda m, t=topic: got[t].append(json.loads(m.data)), 50)
    ros_executor.add_node(probe)
    pipe = {"stdout": subprocess.DEVNULL, "stderr": subprocess.PIPE}
    started["sim"] = _installed(workspace, "sim", "--ros-args", "-r", f"__ns:={ns}", **pipe)
    spin_until(ros_executor, lambda: len(got["thrust"]) >= 100, timeout_s=120)
    started["identifier"] = _installed(workspace, "identifier", "--ros-args", "-r",
                                       f"__ns:={ns}", "--params-file", str(params),
                                       "-p", "hop:=100", **pipe)
    started["gfrf"] = _installed(workspace, "gfrf", "--ros-args", "-r", f"__ns:={ns}",
                                 "-p", "orders:=[1]", **pipe)

    def analysed() -> list[dict[str, Any]]:
        """Ridges of models the probe received (on a busy machine the probe may discover
        the identifier after its first model, which the GFRF node did receive)."""
        ids = {m["model_id"] for m in got["model"]}
        return [r for r in got["ridges"] if r["model_id"] in ids]

    spin_until(ros_executor, lambda: len(got["model"]) >= 2 and bool(analysed()),
               timeout_s=240)
    probe.destroy_node()
    assert {m["output"] for m in got["model"]} == {"speed"}  # the params file
    # -p hop:=100: window number seq ends at sample 100 seq (250 seq by default)
    assert all(m["window"]["stop_index"] == 100 * m["window"]["seq"] for m in got["model"])
    assert all(r["h2"]["skipped"] for r in analysed())  # -p orders:=[1]: no H2
    for name, sig in (("gfrf", signal.SIGINT), ("identifier", signal.SIGTERM),
                      ("sim", signal.SIGINT)):
        proc = started[name]
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0 and "Traceback" not in err, (name, err)
        assert f"{ns}/pmsm_" in err  # its log line names the node in the namespace
