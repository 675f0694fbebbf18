"""pytest fixtures for ROS 2 tests with pmsm_sysid (registered as the ``pytest11`` entry
point ``pmsm_sysid``, so installing the package is enough).

- ``ros_env``: a ``ROS_DOMAIN_ID`` of the test's own (different for each test and each
  pytest-xdist worker), localhost-only discovery and a private ``ROS_LOG_DIR``; yields the id.
- ``ros_context``: an initialised private :class:`rclpy.context.Context` on that domain,
  shut down after the test. Before it, the process is pointed at the package's Fast DDS
  profile (a 0.1 s writer heartbeat, :mod:`pmsm_sysid.dds`) unless it chose a profile or
  a middleware of its own.
- ``ros_executor``: a :class:`rclpy.executors.SingleThreadedExecutor` on ``ros_context``.
- ``sim_motor``: a factory, ``sim_motor(namespace="/x", excitation="paper-speed", seed=0,
  plant=None, **options)``, that starts a simulated motor node (publishing
  ``<namespace>/thrust``, ``/speed`` and ``/position`` at the plant's rate) already added to
  ``ros_executor``; nodes are destroyed after the test.

Example test in another project::

    from geometry_msgs.msg import TwistStamped
    from pmsm_sysid.testing import spin_until

    def test_motor_speed(ros_context, ros_executor, sim_motor):
        sim_motor(namespace="/axis1", excitation="chirp", seed=3)
        probe = rclpy.create_node("probe", context=ros_context)
        got = []
        probe.create_subscription(TwistStamped, "/axis1/speed", got.append, 100)
        ros_executor.add_node(probe)
        spin_until(ros_executor, lambda: len(got) >= 50)

Needs rclpy (``pip install 'pmsm_sysid[ros]'`` or a sourced ROS 2 Jazzy); without it the ROS
fixtures fail with one line saying so, and everything else still runs.
"""

from __future__ import annotations

import hashlib
import itertools
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ..dds import use_packaged_profile

NO_ROS = ("needs rclpy: pip install 'pmsm_sysid[ros]' (the ROS 2 Jazzy wheels) or source a "
          "ROS 2 Jazzy installation")
_counter = itertools.count()


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "ros: needs rclpy (in-process executors)")


def _worker_index() -> int:
    wid = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(wid[2:]) if wid.startswith("gw") and wid[2:].isdigit() else 0


def _session_offset() -> int:
    """Offset shared by the workers of one pytest run (xdist's run uid, else the pid), so
    that test runs started side by side on one host mostly use different domains."""
    uid = os.environ.get("PYTEST_XDIST_TESTRUNUID") or str(os.getpid())
    return int(hashlib.sha1(uid.encode()).hexdigest(), 16) % 130


def next_domain_id() -> int:
    """A ROS_DOMAIN_ID for the next test of this worker, in 100..229 (below rcl's 232)."""
    return 100 + (_session_offset() + _worker_index() * 40 + next(_counter) % 40) % 130


@pytest.fixture
def ros_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """Assign ROS_DOMAIN_ID, localhost discovery and ROS_LOG_DIR for this test; yields the id."""
    domain = next_domain_id()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    log_dir = tmp_path / "ros_log"
    log_dir.mkdir(exist_ok=True)
    monkeypatch.setenv("ROS_LOG_DIR", str(log_dir))
    yield domain


def _rclpy() -> Any:
    try:
        import rclpy
    except ImportError as exc:
        pytest.fail(f"pmsm_sysid ROS fixtures {NO_ROS} ({exc})", pytrace=False)
    return rclpy


@pytest.fixture
def ros_context(ros_env: int) -> Iterator[Any]:
    """An initialised private rclpy Context on the test's own domain; shut down after."""
    rclpy = _rclpy()
    from rclpy.context import Context

    use_packaged_profile()
    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_env)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture
def ros_executor(ros_context: Any) -> Iterator[Any]:
    """A SingleThreadedExecutor on ``ros_context``; shut down after the test."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=ros_context)
    try:
        yield executor
    finally:
        executor.shutdown(timeout_sec=2.0)


@pytest.fixture
def sim_motor(ros_context: Any, ros_executor: Any) -> Iterator[Callable[..., Any]]:
    """Factory of simulated motor nodes on ``ros_executor`` (see the module doc)."""
    from ..nodes.sim_node import MotorSimNode

    nodes: list[Any] = []

    def start(namespace: str = "/pmsm", excitation: str = "paper-speed", seed: int = 0,
              plant: Any = None, **options: Any) -> Any:
        if plant is not None and not hasattr(plant, "mass_kg"):
            from ..core.physics.plant import load_plant

            plant = load_plant(plant)
        suffix = "" if not nodes else f"_{len(nodes) + 1}"
        node = MotorSimNode(context=ros_context, plant=plant, excitation=excitation,
                            seed=seed, namespace=namespace,
                            node_name=options.pop("node_name", "pmsm_sim" + suffix), **options)
        nodes.append(node)
        ros_executor.add_node(node)
        return node

    try:
        yield start
    finally:
        for node in nodes:
            ros_executor.remove_node(node)
            node.destroy_node()
