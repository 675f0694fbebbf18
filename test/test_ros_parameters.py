"""Live parameters through the standard services, as ``ros2 param`` uses them.

A client node in the same process (its own node, talking to ``<ns>/pmsm_identifier`` over
the SetParameters / GetParameters / DescribeParameters services) sets, reads back and
describes the identifier's parameters while the pipeline runs.
"""

from __future__ import annotations

import itertools
import time
import uuid
from typing import Any

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SMALL = {"outputs": ["speed"], "window": 300, "hop": 100, "speed.ny": 4, "speed.nu": 4,
         "speed.terms": 10, "method": "ofr"}


def _wait(pipe: Any, future: Any, timeout_s: float = 60.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while not future.done():
        assert time.monotonic() < deadline, "no answer from the parameter service"
        pipe.executor.spin_once(timeout_sec=0.05)
    return future.result()


def _n_terms(model: dict[str, Any]) -> int:
    return sum(t["name"] != "const" for t in model["terms"])


def test_parameters_set_through_the_service_apply_to_the_next_fits(ros_context: Any) -> None:
    import rclpy
    from rcl_interfaces.msg import ParameterType
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    from pmsm_sysid.app import build_pipeline

    ns = f"/p{uuid.uuid4().hex[:8]}"
    with build_pipeline(["sim", "identifier"], clock="sim", seed=3, namespace=ns,
                        context=ros_context, identifier_params=SMALL) as pipe:
        client_node = rclpy.create_node("param_client", context=ros_context)
        pipe.executor.add_node(client_node)
        try:
            client = AsyncParameterClient(client_node, f"{ns}/pmsm_identifier")
            _ready(pipe, client)
            pipe.run(2.0)
            pipe.finish()
            before = list(pipe.nodes["collector"].model_log)
            sizes = [_n_terms(m) for m in before]
            assert sizes and max(sizes) <= 10 and min(sizes) > 3, sizes

            # refused, with the reason; nothing changes
            bad = _wait(pipe, client.set_parameters([Parameter("hop", value=-5)])).results[0]
            assert not bad.successful and "hop" in bad.reason and "range" in bad.reason
            odd = _wait(pipe, client.set_parameters_atomically([
                Parameter("hop", value=400), Parameter("window", value=300)])).result
            assert not odd.successful and "at most window" in odd.reason
            typed = _wait(pipe, client.set_parameters([Parameter("speed.terms",
                                                                 value="six")])).results[0]
            assert not typed.successful and "INTEGER" in typed.reason
            fixed = _wait(pipe, client.set_parameters([Parameter("queue_size",
                                                                 value=5)])).results[0]
            assert not fixed.successful and "read-only" in fixed.reason

            # accepted: 3 terms from the next window on, windows of 200 every 50 samples
            ok = _wait(pipe, client.set_parameters_atomically([
                Parameter("speed.terms", value=3), Parameter("window", value=200),
                Parameter("hop", value=50)])).result
            assert ok.successful, ok.reason
            got = _wait(pipe, client.get_parameters(["speed.terms", "window", "hop",
                                                     "queue_size"])).values
            assert [v.integer_value for v in got] == [3, 200, 50, 1]
            desc = _wait(pipe, client.describe_parameters(["hop", "min_r2"])).descriptors
            assert desc[0].type == ParameterType.PARAMETER_INTEGER and desc[0].description
            assert (desc[0].integer_range[0].from_value, desc[0].integer_range[0].to_value) \
                == (1, 1_000_000)
            assert desc[1].floating_point_range[0].to_value == 1.0
            seen = pipe.identifier.models_published
            pipe.run(2.0)
            pipe.finish()
            after = list(pipe.nodes["collector"].model_log)[seen:]
        finally:
            pipe.executor.remove_node(client_node)
            client_node.destroy_node()
    new = [m for m in after if m["window"]["n_samples"] == 200]
    assert len(new) >= 15  # 1000 samples at hop 50
    assert all(_n_terms(m) <= 3 for m in new)
    assert all(m["window"]["n_samples"] in (200, 300) for m in after)
    stops = [m["window"]["stop_index"] for m in new]
    assert {b - a for a, b in itertools.pairwise(stops)} == {50}
    assert pipe.identifier.params["speed.terms"] == 3


def _ready(pipe: Any, client: Any) -> None:
    deadline = time.monotonic() + 30
    while not client.services_are_ready():
        assert time.monotonic() < deadline, "parameter services not discovered"
        pipe.executor.spin_once(timeout_sec=0.05)


def test_a_resized_window_ring_keeps_the_newest_contiguous_samples() -> None:
    """window 6 -> 4 mid-stream: the next window is cut from samples already held, on the
    new hop grid, with the newest values."""
    import numpy as np

    from pmsm_sysid.core.online.streaming import Sample
    from pmsm_sysid.core.online.windows import WindowScheduler

    ring = WindowScheduler(window=6, hop=3, history=1, n_signals=1, signals=("x",))
    cut = [ring.push(Sample(k, 1000 * k, (float(k),))) for k in range(10)]
    assert [w.stop_index for w in cut if w is not None] == [9]
    ring.resize(window=4, hop=2, history=0)
    w = ring.push(Sample(10, 10_000, (10.0,)))
    assert w is None  # 11 is not on the hop-2 grid
    w = ring.push(Sample(11, 11_000, (11.0,)))
    assert w is not None and (w.start_index, w.stop_index) == (8, 12)
    assert np.array_equal(w.values[:, 0], [8.0, 9.0, 10.0, 11.0])
    ring.resize(window=8, hop=2, history=0)  # more than is held: wait for 8 contiguous
    assert ring.push(Sample(12, 12_000, (12.0,))) is None
    assert ring.push(Sample(13, 13_000, (13.0,))) is None
    w = ring.push(Sample(15, 15_000, (15.0,)))
    assert w is None  # the gap restarts the count
