"""Test helpers for projects that use pmsm_sysid, and its pytest plugin.

Installing pmsm_sysid registers :mod:`pmsm_sysid.testing.pytest_plugin` with pytest (a
``pytest11`` entry point): any test suite gets the fixtures ``ros_env``, ``ros_context``,
``ros_executor`` and ``sim_motor`` without a conftest. This package imports no ROS module
until a fixture or helper needs one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


def spin_until(executor: Any, done: Callable[[], bool], timeout_s: float = 60.0,
               step_s: float = 0.05) -> None:
    """Spin ``executor`` one callback at a time until ``done()`` is true.

    ``timeout_s`` is a generous safety net for a hung test, not a measure of speed: the
    condition decides. Raises :class:`TimeoutError` naming the limit when it passes.

    Example (in a test that uses the plugin's fixtures)::

        motor = sim_motor(namespace="/x")
        spin_until(ros_executor, lambda: motor.published >= 100)
    """
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise TimeoutError(f"condition still false after {timeout_s:g} s of spinning")
        executor.spin_once(timeout_sec=step_s)
