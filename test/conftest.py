"""Shared fixtures. The ROS fixtures (``ros_env``, ``ros_context``, ``ros_executor``,
``sim_motor``: a private domain id, log dir and rclpy Context per test) come from the
package's own pytest plugin, :mod:`pmsm_sysid.testing.pytest_plugin`, which installing the
package registers with pytest; a source checkout that is not installed loads it here."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
EMPS_MAT = SHARED / "data" / "emps" / "DATA_EMPS.mat"
PLUGIN = "pmsm_sysid.testing.pytest_plugin"

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"


def pytest_configure(config: pytest.Config) -> None:
    """Load the plugin unless its entry point already did (never register it twice)."""
    import importlib

    manager = config.pluginmanager
    if manager.is_registered(importlib.import_module(PLUGIN)):
        return
    manager.register(importlib.import_module(PLUGIN), "pmsm_sysid")


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared beside the repo; a test that needs it fails (not skips) if it is missing."""
    assert SHARED.is_dir(), f"../shared not found at {SHARED}"
    return SHARED
