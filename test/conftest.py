"""Shared fixtures. ROS tests get a private domain id, log dir and rclpy Context each."""

from __future__ import annotations

import hashlib
import itertools
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
EMPS_MAT = SHARED / "data" / "emps" / "DATA_EMPS.mat"

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
_counter = itertools.count()


def _worker_index() -> int:
    wid = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(wid[2:]) if wid.startswith("gw") and wid[2:].isdigit() else 0


def _session_offset() -> int:
    """Offset shared by the workers of one pytest run (xdist's run uid, else the pid), so
    that test runs started side by side on one host mostly use different domains."""
    uid = os.environ.get("PYTEST_XDIST_TESTRUNUID") or str(os.getpid())
    return int(hashlib.sha1(uid.encode()).hexdigest(), 16) % 130


_OFFSET = _session_offset()


def next_domain_id() -> int:
    """A ROS_DOMAIN_ID unique to this xdist worker and test (<= 232)."""
    return 100 + (_OFFSET + _worker_index() * 40 + next(_counter) % 40) % 130


@pytest.fixture
def ros_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """Assign ROS_DOMAIN_ID / ROS_LOG_DIR for this test; yields the domain id."""
    domain = next_domain_id()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    log_dir = tmp_path / "ros_log"
    log_dir.mkdir()
    monkeypatch.setenv("ROS_LOG_DIR", str(log_dir))
    yield domain


@pytest.fixture
def ros_context(ros_env: int) -> Iterator[object]:
    """An initialised private rclpy Context on the test's own domain; shut down after."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_env)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared beside the repo; a test that needs it fails (not skips) if it is missing."""
    assert SHARED.is_dir(), f"../shared not found at {SHARED}"
    return SHARED
