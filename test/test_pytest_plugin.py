"""The pytest plugin as another project uses it: a project directory of its own (no conftest,
nothing of this repository's test/ on the path) whose test spins a probe subscriber on the
plugin's executor and receives the simulated motor's speed samples.

The plugin is found through the package's ``pytest11`` entry point, read from metadata
built from this checkout's setup.py (so the test checks what ``pip install`` declares)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

PROBE_TEST = '''
import numpy as np
import rclpy
from geometry_msgs.msg import TwistStamped

import pmsm_sysid as ps
from pmsm_sysid.testing import spin_until


def test_probe_receives_the_motor_speed(ros_context, ros_executor, sim_motor, ros_env):
    assert ros_context.get_domain_id() == ros_env
    motor = sim_motor(namespace="/axis7", excitation="chirp", seed=3, clock="sim")
    probe = rclpy.create_node("probe", context=ros_context)
    got = []
    probe.create_subscription(TwistStamped, "/axis7/speed", got.append, 1000)
    ros_executor.add_node(probe)
    spin_until(ros_executor, lambda: len(got) >= 200)
    # sim clock: sample k is stamped k / fs; the values are the offline simulation's
    k = np.array([round((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9) * 500.0)
                  for m in got])
    speed = np.array([m.twist.linear.x for m in got])
    assert (np.diff(k) == 1).all()
    offline = ps.simulate(excitation="chirp", seed=3, duration=(k[-1] + 1) / 500.0)
    np.testing.assert_allclose(speed, offline.speed[k], rtol=0, atol=1e-9)
    assert np.abs(speed).max() > 1e-3
    assert motor.published >= len(got)


def test_two_motors_on_one_executor(ros_context, ros_executor, sim_motor):
    a, b = sim_motor(namespace="/a"), sim_motor(namespace="/b", seed=1)
    spin_until(ros_executor, lambda: a.published >= 20 and b.published >= 20)
'''

NO_ROS_TEST = '''
import sys

sys.modules["rclpy"] = None  # as if ROS 2 were not installed


def test_wants_ros(ros_context):
    pass


def test_needs_no_ros():
    import pmsm_sysid as ps

    assert len(ps.simulate(duration=0.1)) == 50
'''


@pytest.fixture(scope="module")
def metadata_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``pmsm_sysid.egg-info`` (with entry_points.txt) built from this checkout's setup.py."""
    out = tmp_path_factory.mktemp("meta")
    proc = subprocess.run([sys.executable, "setup.py", "-q", "egg_info", "--egg-base", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    entry_points = (out / "pmsm_sysid.egg-info" / "entry_points.txt").read_text()
    assert "[pytest11]" in entry_points
    assert "pmsm_sysid = pmsm_sysid.testing.pytest_plugin" in entry_points
    return out


def _run_project(tmp_path: Path, metadata: Path, name: str, text: str
                 ) -> subprocess.CompletedProcess[str]:
    project = tmp_path / "other_project"
    (project / "tests").mkdir(parents=True)
    (project / "tests" / name).write_text(text)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(metadata), str(REPO)])}
    env.pop("PYTEST_XDIST_WORKER", None)
    env.pop("PYTEST_ADDOPTS", None)
    # -p no:cacheprovider: leave nothing behind; the plugin arrives by its entry point only
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-p", "no:xdist", "tests"], cwd=project, env=env,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.ros
def test_another_project_receives_the_motor_speed(tmp_path: Path, metadata_dir: Path) -> None:
    proc = _run_project(tmp_path, metadata_dir, "test_probe.py", PROBE_TEST)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 passed" in proc.stdout


@pytest.mark.slow
def test_without_rclpy_the_ros_fixtures_fail_with_one_line(tmp_path: Path,
                                                          metadata_dir: Path) -> None:
    proc = _run_project(tmp_path, metadata_dir, "test_no_ros.py", NO_ROS_TEST)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "1 passed" in proc.stdout and "1 error" in proc.stdout
    assert "needs rclpy: pip install 'pmsm_sysid[ros]'" in proc.stdout
