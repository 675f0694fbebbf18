"""The sim clock's cheap paths: serialized sample messages, /clock per burst, the fit wake-up.

The stepped pipeline publishes the sim's samples as CDR bytes patched in place
(:class:`pmsm_sysid.rosutil.SampleEncoder`), /clock once per burst unless someone listens,
and sleeps until the fitting thread takes the waiting window; none of it may change a
sample, a stamp or a window.
"""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import ExcitationSource
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant

pytestmark = pytest.mark.ros
REPO = Path(__file__).resolve().parents[1]
NOISY = REPO / "plants" / "nominal_noisy.yaml"


@pytest.mark.parametrize("frame_id", ["", "pmsm", "abc", "a_longer_frame_id_of_23"])
def test_encoded_samples_are_the_serialized_messages(frame_id: str) -> None:
    """Same length as ``serialize_message``, the same bytes but the alignment padding (which
    the middleware leaves as it finds it), and they deserialize to the very messages."""
    from rclpy.serialization import deserialize_message, serialize_message
    from rosgraph_msgs.msg import Clock

    from pmsm_sysid.bagio.cdr import decode_stamped
    from pmsm_sysid.rosutil import SampleEncoder, make_sample_messages, stamp_from_ns

    enc = SampleEncoder(frame_id)
    assert enc.raw
    rng = np.random.default_rng(3)
    pad = range(16 + len(frame_id) + 1, enc._value_at)
    for stamp in (0, 1, 999_999_999, 10**9, 2**31 * 10**9 - 1, *rng.integers(0, 2**31 * 10**9, 20)):
        values = rng.normal(size=3) * 10.0 ** rng.integers(-9, 9, 3)
        got = enc.encode(int(stamp), *values)
        msgs = make_sample_messages(int(stamp), *values, frame_id=frame_id)
        for data, msg in zip(got, msgs.values(), strict=True):
            ref = bytes(serialize_message(msg))
            assert len(data) == len(ref)
            same = [a == b for a, b in zip(data, ref, strict=True)]
            assert all(s for i, s in enumerate(same) if i not in pad)
            assert deserialize_message(data, type(msg)) == msg
        assert [decode_stamped(d) for d in got] == [(int(stamp), v) for v in values]
        clock = Clock(clock=stamp_from_ns(int(stamp)))
        assert enc.clock(int(stamp)) == bytes(serialize_message(clock))


def test_an_unexpected_layout_falls_back_to_serializing_messages(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from rclpy.serialization import serialize_message

    from pmsm_sysid.rosutil import SampleEncoder, make_sample_messages

    monkeypatch.setattr(SampleEncoder, "_layout_holds", lambda self: False)
    enc = SampleEncoder("pmsm")
    assert not enc.raw
    msgs = make_sample_messages(1_500_000_000, 1.0, -2.0, 3e-6, "pmsm")
    assert enc.encode(1_500_000_000, 1.0, -2.0, 3e-6) == tuple(
        bytes(serialize_message(m)) for m in msgs.values())


class _ClockSpy:
    """Stands in for the sim's /clock publisher: records what is published."""

    def __init__(self, subscribers: int) -> None:
        self.subscribers = subscribers
        self.stamps: list[int] = []

    def get_subscription_count(self) -> int:
        return self.subscribers

    def publish(self, data: bytes) -> None:
        from rclpy.serialization import deserialize_message
        from rosgraph_msgs.msg import Clock

        from pmsm_sysid.rosutil import stamp_to_ns

        self.stamps.append(stamp_to_ns(deserialize_message(data, Clock).clock))


@pytest.mark.parametrize("subscribers", [0, 1])
def test_clock_per_burst_unless_someone_listens(ros_context: Any, subscribers: int) -> None:
    """Nobody on /clock: one /clock per burst, first, at the burst's newest stamp (no sample
    is ever ahead of the clock). Someone there: one per sample, as before each sample."""
    from pmsm_sysid.nodes.sim_node import MotorSimNode

    sim = MotorSimNode(context=ros_context, clock="sim", rate=0.0, max_samples=450,
                       namespace=f"/t{uuid.uuid4().hex[:10]}")
    try:
        spy = _ClockSpy(subscribers)
        sim._clock_pub = spy
        assert [sim.step(200), sim.step(200), sim.step(200), sim.step(5)] == [200, 200, 50, 0]
    finally:
        sim.destroy_node()
    period = 2_000_000
    if subscribers:
        assert spy.stamps == [k * period for k in range(450)]
    else:
        assert spy.stamps == [199 * period, 399 * period, 449 * period]
    assert sim.finished and sim.published == 450


def test_bursts_publish_the_offline_simulation_bit_for_bit(ros_context: Any) -> None:
    """Bursts of 250 (the pipeline's size) reach a subscriber as ``simulate`` computes them,
    and a /clock subscriber gets every sample's stamp."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock

    from pmsm_sysid.nodes.sim_node import MotorSimNode
    from pmsm_sysid.rosutil import data_qos, message_class, sample_value, stamp_to_ns
    from pmsm_sysid.topics import INPUT_TYPES, input_topic

    plant, seed, n, ns = load_plant(NOISY), 5, 1000, f"/t{uuid.uuid4().hex[:10]}"
    got: dict[str, list[tuple[int, float]]] = {s: [] for s in INPUT_TYPES}
    clocks: list[int] = []
    node = Node("listener", context=ros_context)
    for sig, type_name in INPUT_TYPES.items():
        node.create_subscription(
            message_class(type_name), input_topic(ns, sig),
            lambda m, s=sig: got[s].append((stamp_to_ns(m.header.stamp), sample_value(s, m))),
            data_qos(5000))
    node.create_subscription(Clock, f"{ns}/clock", lambda m: clocks.append(stamp_to_ns(m.clock)),
                             data_qos(5000))
    sim = MotorSimNode(context=ros_context, plant=plant, excitation="multisine", seed=seed,
                       clock="sim", rate=0.0, max_samples=n, namespace=ns,
                       cli_args=["--ros-args", "-r", f"/clock:={ns}/clock"])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    try:
        sim.stop_timer()
        pubs = [*sim.input_publishers, sim._clock_pub]
        while not all(p.get_subscription_count() for p in pubs):
            ex.spin_once(timeout_sec=0.05)
        while sim.published < n:
            sim.step(250)
        while min(len(v) for v in got.values()) < n or len(clocks) < n:
            ex.spin_once(timeout_sec=1.0)
    finally:
        ex.shutdown()
        sim.destroy_node()
        node.destroy_node()
    rec = simulate(plant, ExcitationSource("multisine", 500.0, seed=seed).block(0, n), seed=seed)
    stamps = np.arange(n, dtype=np.int64) * 2_000_000
    for sig, truth in (("thrust", rec.thrust), ("speed", rec.speed),
                       ("position", rec.position)):
        assert [s for s, _ in got[sig]] == stamps.tolist(), sig
        assert np.array_equal([v for _, v in got[sig]], truth), sig
    assert clocks == stamps.tolist()


def test_each_window_taken_wakes_the_executor(ros_context: Any) -> None:
    """The fitting thread's take of a window triggers the identifier's guard condition: an
    executor waiting for it returns, and runs its callback."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from pmsm_sysid.nodes.identifier_node import IdentifierNode
    from pmsm_sysid.nodes.params import SwitchableProcessor

    calls: list[str] = []
    proc = SwitchableProcessor(lambda w: calls.append(f"fit {w}") or w, lambda w: 0)
    proc.on_take = lambda: calls.append("taken")
    assert proc("a") == "a" and calls == ["taken", "fit a"]

    ident = IdentifierNode(context=ros_context, namespace=f"/t{uuid.uuid4().hex[:10]}",
                           parameter_overrides=[Parameter("fit_worker", value="thread")])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(ident)
    try:
        guard = ident.wake_on_window()
        woken: list[bool] = []
        guard.callback = lambda: woken.append(True)
        assert ident._fit.on_take == guard.trigger
        ident._fit.on_take()
        for _ in range(100):  # other callbacks (its timers) may come first
            ex.spin_once(timeout_sec=5.0)
            if woken:
                break
        assert woken == [True]
    finally:
        ex.shutdown()
        ident.destroy_node()
