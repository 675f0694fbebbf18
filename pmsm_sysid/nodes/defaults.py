"""The identifier node's parameters and their defaults, importable without ROS (the
offline tests and benchmarks feed them to :func:`pmsm_sysid.core.online.tracker.tracker_config`
as the node does)."""

from __future__ import annotations

from typing import Any

__all__ = ["IDENTIFIER_DEFAULTS"]

#: Parameters and their defaults (paper structures: speed ny=30 nu=40, position ny=10 nu=10;
#: position as its increment per sample, linear: bounded in free run).
IDENTIFIER_DEFAULTS: dict[str, Any] = {
    "input_layout": "topics", "joint_name": "", "joint_state_topic": "/joint_states",
    "window": 1000, "hop": 250, "queue_size": 1, "sample_rate_hz": 0.0, "tolerance_s": 0.0,
    "outputs": ["speed", "position"], "method": "ofr", "criterion": "terms",
    "speed.ny": 30, "speed.nu": 40, "speed.degree": 2, "speed.delay": 1, "speed.terms": 15,
    "speed.form": "level",
    "position.ny": 10, "position.nu": 10, "position.degree": 1, "position.delay": 1,
    "position.terms": 15, "position.form": "difference", "min_r2": 0.9, "change.s_confirm": 7.0,
    "change.baseline": 48, "change.warmup": 8, "change.min_r2": 0.99,
    "publish_period_s": 0.05, "stale_after_s": 1.0,
    "speed_source": "auto", "inputs_report_s": 3.0, "fit_worker": "process",
}
