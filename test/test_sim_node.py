"""MotorSimNode: samples equal the offline simulation; parameters change the plant at run time."""

from __future__ import annotations

import math
import time
import uuid
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import ExcitationSource
from pmsm_sysid.core.physics.motor import MotorSimulator, simulate
from pmsm_sysid.core.physics.plant import Cogging, load_plant, nominal_plant

pytestmark = pytest.mark.ros
REPO = Path(__file__).resolve().parents[1]
NOISY = REPO / "plants" / "nominal_noisy.yaml"
COGGING = REPO / "plants" / "cogging.yaml"


def _unique_ns() -> str:
    """A namespace of its own, so test runs side by side on one host cannot cross-talk."""
    return f"/t{uuid.uuid4().hex[:10]}"


def _remap_clock(ns: str) -> list[str]:
    return ["--ros-args", "-r", f"/clock:={ns}/clock"]


class Collector:
    """A node subscribing to the three topics (and <ns>/clock) with the data QoS."""

    def __init__(self, context: Any, namespace: str) -> None:
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock

        from pmsm_sysid.rosutil import data_qos, message_class, sample_value, stamp_to_ns
        from pmsm_sysid.topics import INPUT_TYPES, input_topic

        self.node = Node("collector", context=context)
        self.data: dict[str, list[tuple[int, float]]] = {s: [] for s in INPUT_TYPES}
        self.clock: list[int] = []
        for sig, type_name in INPUT_TYPES.items():
            def cb(msg: Any, sig: str = sig) -> None:
                self.data[sig].append((stamp_to_ns(msg.header.stamp), sample_value(sig, msg)))
            self.node.create_subscription(message_class(type_name), input_topic(namespace, sig),
                                          cb, data_qos())
        self.node.create_subscription(Clock, f"{namespace}/clock",
                                      lambda m: self.clock.append(stamp_to_ns(m.clock)),
                                      data_qos())

    def count(self) -> int:
        return min(len(v) for v in self.data.values())

    def arrays(self, sig: str) -> tuple[np.ndarray, np.ndarray]:
        stamps, values = zip(*self.data[sig], strict=True)
        return np.array(stamps, dtype=np.int64), np.array(values)


def _spin_until(ex: Any, done: Any, timeout_s: float = 30.0, state: Any = None) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, f"timed out{'' if state is None else state()}"
        ex.spin_once(timeout_sec=0.05)


def _wait_matched(ex: Any, sim: Any) -> None:
    _spin_until(ex, lambda: all(p.get_subscription_count() >= 1 for p in sim._pubs.values()))


def test_sim_clock_samples_equal_offline_simulation(ros_context: Any) -> None:
    """N = 2000 samples at 500 Hz, sim clock as fast as possible, noisy plant, seed 7."""
    from rclpy.executors import SingleThreadedExecutor

    from pmsm_sysid.nodes.sim_node import MotorSimNode

    plant, seed, n = load_plant(NOISY), 7, 2000
    ns = _unique_ns()
    col = Collector(ros_context, ns)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(col.node)
    sim = MotorSimNode(context=ros_context, plant=plant, excitation="multisine", seed=seed,
                       clock="sim", rate=0.0, max_samples=n, namespace=ns,
                       cli_args=_remap_clock(ns))
    try:
        _wait_matched(ex, sim)  # the subscriber is matched before the first sample
        ex.add_node(sim)
        _spin_until(ex, lambda: col.count() >= n and len(col.clock) >= n, 10,
                    lambda: f": {col.count()} samples, {len(col.clock)} clocks of {n}")
        for _ in range(20):     # nothing beyond max_samples arrives
            ex.spin_once(timeout_sec=0.01)
    finally:
        ex.shutdown()
        sim.destroy_node()
        col.node.destroy_node()
    thrust = ExcitationSource("multisine", 500.0, seed=seed).block(0, n)
    rec = simulate(plant, thrust, seed=seed)
    expected_stamps = np.round(rec.t * 1e9).astype(np.int64)
    assert np.all(expected_stamps == np.arange(n, dtype=np.int64) * 2_000_000)
    for sig, truth in (("thrust", rec.thrust), ("speed", rec.speed),
                       ("position", rec.position)):
        stamps, values = col.arrays(sig)
        assert len(stamps) == n, sig                   # all received, nothing extra
        assert np.all(np.diff(stamps) > 0), sig        # in order, strictly increasing
        assert np.array_equal(stamps, expected_stamps), sig
        assert np.array_equal(values, truth), sig      # bit for bit
    assert col.clock == expected_stamps.tolist()       # /clock = t_k, one per sample
    assert np.std(rec.speed) > 0.01                    # the motor actually moved


def test_wall_clock_stamps_are_regular_and_current(ros_context: Any) -> None:
    from rclpy.executors import SingleThreadedExecutor

    from pmsm_sysid.nodes.sim_node import MotorSimNode

    ns = _unique_ns()
    col = Collector(ros_context, ns)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(col.node)
    before = time.time_ns()
    sim = MotorSimNode(context=ros_context, max_samples=100, namespace=ns,
                       cli_args=_remap_clock(ns))
    try:
        _wait_matched(ex, sim)
        ex.add_node(sim)
        _spin_until(ex, lambda: col.count() >= 100)
    finally:
        ex.shutdown()
        sim.destroy_node()
        col.node.destroy_node()
    stamps, _ = col.arrays("speed")
    assert np.all(np.diff(stamps) == 2_000_000)
    assert stamps[0] >= before and stamps[0] - before < 60 * 10**9
    assert col.clock == []  # no /clock with the wall clock
    assert [s for s, _ in col.data["thrust"]] == stamps.tolist()


def test_wall_clock_starts_with_the_first_sample_after_a_hold(ros_context: Any) -> None:
    """A sim held after it was created (as ``run --record`` holds it until the recorder is
    ready) stamps its first sample when it publishes it, not when it was created: every stamp
    is the wall time of its sample, so a recording cut by a crash ends at the crash. Both
    bounds are orderings of events (released before the first stamp, each stamp before its
    reception), not durations."""
    from geometry_msgs.msg import TwistStamped
    from rclpy.executors import SingleThreadedExecutor

    from pmsm_sysid.nodes.sim_node import MotorSimNode
    from pmsm_sysid.rosutil import data_qos

    ns = _unique_ns()
    col = Collector(ros_context, ns)
    received: list[int] = []
    col.node.create_subscription(TwistStamped, f"{ns}/speed",  # when each speed arrives
                                 lambda _m: received.append(time.time_ns()), data_qos())
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(col.node)
    sim = MotorSimNode(context=ros_context, max_samples=100, namespace=ns,
                       cli_args=_remap_clock(ns))
    try:
        sim.stop_timer()
        ex.add_node(sim)
        _wait_matched(ex, sim)
        held = time.monotonic()
        _spin_until(ex, lambda: time.monotonic() - held > 0.3)  # held: nothing published
        assert sim.published == 0
        released = time.time_ns()
        sim.start_timer()
        _spin_until(ex, lambda: col.count() >= 100 and len(received) >= 100)
    finally:
        ex.shutdown()
        sim.destroy_node()
        col.node.destroy_node()
    stamps, _ = col.arrays("speed")
    assert np.all(np.diff(stamps) == 2_000_000)
    assert stamps[0] >= released
    slew_ns = 1_000_000  # the wall clock may be slewed against the monotonic one that paces
    assert np.all(stamps <= np.array(received[:100]) + slew_ns)


def test_parameters_round_trip_a_plant_file() -> None:
    from pmsm_sysid.nodes.sim_node import plant_from_parameters, plant_parameters

    plant = load_plant(COGGING)
    flat = plant_parameters(plant)
    assert flat["cogging.enabled"] is True and flat["coulomb_friction.enabled"] is False
    assert flat["cogging.pitch_m"] == 0.005 and flat["mass_kg"] == plant.mass_kg
    assert plant_from_parameters(flat) == plant
    assert plant_from_parameters(plant_parameters(nominal_plant())) == nominal_plant()


def test_cogging_switched_on_at_run_time(ros_context: Any) -> None:
    """Parameters set mid-run add cogging from sample 500 on; speeds follow the physics."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from pmsm_sysid.nodes.sim_node import MotorSimNode

    plant, seed, k_on = nominal_plant(), 3, 500
    amp, pitch, phase = 4.0, 0.05, 0.3
    ns = _unique_ns()
    col = Collector(ros_context, ns)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(col.node)
    sim = MotorSimNode(context=ros_context, plant=plant, seed=seed, clock="sim", rate=0.0,
                       namespace=ns, cli_args=_remap_clock(ns))
    sim.stop_timer()  # stepped by hand below
    try:
        _wait_matched(ex, sim)
        ex.add_node(sim)
        sim.step(k_on)
        bad = sim.set_parameters_atomically([Parameter("cogging.enabled", value=True)])
        assert not bad.successful and "pitch_m must be > 0" in bad.reason
        fixed = sim.set_parameters([Parameter("seed", value=4)])[0]
        assert not fixed.successful and "seed" in fixed.reason
        ok = sim.set_parameters_atomically([
            Parameter("cogging.amplitude_n", value=amp), Parameter("cogging.pitch_m", value=pitch),
            Parameter("cogging.phase_rad", value=phase), Parameter("cogging.enabled", value=True)])
        assert ok.successful, ok.reason
        assert sim.get_parameter("cogging.enabled").value is True
        sim.step(k_on)
        _spin_until(ex, lambda: col.count() >= 2 * k_on)
    finally:
        ex.shutdown()
        sim.destroy_node()
        col.node.destroy_node()
    _, speed = col.arrays("speed")
    _, position = col.arrays("position")
    thrust = ExcitationSource("paper-speed", 500.0, seed=seed).block(0, 2 * k_on)
    plain = simulate(plant, thrust, seed=seed)
    # before the switch: the nominal motor; after: differs
    assert np.array_equal(speed[:k_on + 1], plain.speed[:k_on + 1])
    assert not np.array_equal(speed[k_on + 1:], plain.speed[k_on + 1:])
    # the same switch offline with set_plant gives the same numbers bit for bit
    cog = replace(plant, cogging=Cogging(amplitude_n=amp, pitch_m=pitch, phase_rad=phase))
    off = MotorSimulator(plant, seed=seed)
    ref = []
    for k in range(2 * k_on):
        if k == k_on:
            off.set_plant(cog)
        ref.append(off.measure()[0])
        off.advance(thrust[k])
    assert np.array_equal(speed, np.array(ref))
    # independent check of the first step: a force F_c held over one period T on
    # M dv/dt = -B v - F_c changes v by -F_c/B (1 - exp(-B T / M)); F_c is taken at the
    # mid-step position (x moves under 1% of a pitch in one sample).
    x = 0.5 * (position[k_on] + plain.position[k_on + 1])
    f_cog = amp * math.sin(2 * math.pi * x / pitch + phase)
    b, m, t = plant.viscous_n_per_mps, plant.mass_kg, 1 / 500
    expected_dv = -f_cog / b * (1 - math.exp(-b * t / m))
    assert abs(expected_dv) > 1e-3
    assert speed[k_on + 1] - plain.speed[k_on + 1] == pytest.approx(expected_dv, rel=0.03)


def test_bad_initial_parameters_raise_one_clear_error(ros_context: Any) -> None:
    from pmsm_sysid.core.errors import ExcitationError, PmsmSysidError
    from pmsm_sysid.nodes.sim_node import MotorSimNode

    with pytest.raises(ExcitationError, match="unknown excitation 'sine'"):
        MotorSimNode(context=ros_context, excitation="sine")
    with pytest.raises(PmsmSysidError, match="rate applies to clock=sim only"):
        MotorSimNode(context=ros_context, clock="wall", rate=2.0)


def test_run_time_rate_excitation_and_rejections(ros_context: Any) -> None:
    """rate retimes the node, excitation switches at the current k, bad values are refused."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from pmsm_sysid.nodes.sim_node import MotorSimNode

    ns = _unique_ns()
    col = Collector(ros_context, ns)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(col.node)
    sim = MotorSimNode(context=ros_context, clock="sim", rate=0.0, seed=2, namespace=ns,
                       cli_args=_remap_clock(ns))
    try:
        sim.stop_timer()
        assert sim._timer_period() == 0.0
        assert sim.set_parameters([Parameter("rate", value=2.0)])[0].successful
        assert sim._timer_period() == 0.001
        sim.stop_timer()
        for name, value, reason in [("clock", "wall", "read-only parameter: clock"),
                                    ("mass_kg", -1.0, "mass_kg must be > 0"),
                                    ("excitation", "sine", "unknown excitation"),
                                    ("rate", -1.0, "rate must be >= 0")]:
            res = sim.set_parameters([Parameter(name, value=value)])[0]
            assert not res.successful and reason in res.reason, (name, res.reason)
        assert sim.stepper.sim.plant == nominal_plant()
        _wait_matched(ex, sim)
        ex.add_node(sim)
        sim.step(10)
        assert sim.set_parameters([Parameter("excitation", value="chirp")])[0].successful
        sim.step(5)
        _spin_until(ex, lambda: col.count() >= 15)
    finally:
        ex.shutdown()
        sim.destroy_node()
        col.node.destroy_node()
    _, thrust = col.arrays("thrust")
    assert np.array_equal(thrust[:10], ExcitationSource("paper-speed", 500.0, seed=2).block(0, 10))
    # the amplitude parameter keeps its value (50 N) across the switch
    chirp = ExcitationSource("chirp", 500.0, seed=2, amplitude_n=50.0).block(10, 5)
    assert np.array_equal(thrust[10:], chirp)
