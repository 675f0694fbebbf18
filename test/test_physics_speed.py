"""The simulator's fast paths give what they stand for, bit for bit: the effect force taken
apart per plant (against the one formula ``motor._effects`` that ``effects_force`` also uses)
and the noise drawn in blocks (against one ``standard_normal()`` per draw), in open and
closed loop, for every effect block alone and all together, with noise on and off."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.physics import closed_loop, motor
from pmsm_sysid.core.physics.plant import (
    EFFECT_BLOCKS,
    Cogging,
    CoulombFriction,
    ForceOffset,
    Harmonic,
    Noise,
    Plant,
    Quantisation,
    Spring,
    StribeckFriction,
    ThrustLag,
    ThrustRipple,
    TransportDelay,
    nominal_plant,
)
from pmsm_sysid.core.recording.signals import Recording

NOISE = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0, thrust_std=0.3)
BLOCKS: dict[str, Any] = {
    "cogging": Cogging(3.0, 0.005, 0.5, (Harmonic(2, 1.0), Harmonic(3, 0.3, 1.2))),
    "coulomb_friction": CoulombFriction(2.0),
    "stribeck_friction": StribeckFriction(1.0, 0.01),
    "force_offset": ForceOffset(-0.5),
    "thrust_ripple": ThrustRipple(0.03, 0.032, 0.4),
    "thrust_lag": ThrustLag(0.0016 / 3.8835),
    "transport_delay": TransportDelay(0.0013),
    "spring": Spring(20.0),
    "noise": NOISE,
    "quantisation": Quantisation(position_m=1e-6, speed_mps=1e-4),
}
N = 400


def _plants() -> dict[str, Plant]:
    nom = nominal_plant()
    everything = {k: b for k, b in BLOCKS.items() if k != "quantisation"}  # (it rounds the bits)
    out = {"nominal": nom, "all but quantisation": nom.with_effects(**everything),
           "slow lag, friction": nom.with_effects(thrust_lag=ThrustLag(0.01),
                                                  coulomb_friction=CoulombFriction(4.0),
                                                  noise=NOISE),
           "whole-sample delay": nom.with_effects(transport_delay=TransportDelay(0.006)),
           "stiff friction": nom.with_effects(coulomb_friction=CoulombFriction(40.0)),
           "cogging without harmonics": nom.with_effects(cogging=Cogging(0.7, 0.008, 0.3))}
    for name, block in BLOCKS.items():
        out[name] = nom.with_effects(**{name: block})
        out[f"{name} + noise"] = nom.with_effects(**{name: block, "noise": NOISE})
    return out


def _drive(seed: int) -> np.ndarray:
    """Rest (no thrust), then a sine with steps: many reversals and stops of the speed."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 500.0
    u = 40 * np.sin(2 * np.pi * 16.5 * t) + np.repeat(rng.uniform(-15, 15, N // 50), 50)
    u[:40] = 0.0
    return u


def _recordings(plant: Plant, seed: int) -> list[Recording]:
    u = _drive(seed)
    ref = closed_loop.reference_trajectory(N, plant.sample_rate_hz, (0.002, 0.0005),
                                           (3.0, 11.0), fade_s=0.1)
    loop = closed_loop.PositionLoop.for_bandwidth(plant, 15.0)
    return [motor.simulate(plant, u, seed=seed),
            closed_loop.run_closed_loop(plant, ref, loop, seed=seed, injection=0.2 * u,
                                        disturbance=np.roll(0.1 * u, 7))]


class _OneDrawAtATime:
    """What the block draws stand for: one ``standard_normal()`` per value."""

    def __init__(self, rng: np.random.Generator) -> None:
        self._rng = rng

    def draw(self) -> float:
        return float(self._rng.standard_normal())


def _one_formula(plant: Plant) -> Callable[[float, float, float], float]:
    """What the per-plant effect force stands for: the formula ``effects_force`` uses."""
    def effects(x: float, v: float, f: float) -> float:
        return float(motor._effects(plant, x, v, f, math.sin, math.exp, math.tanh))

    return effects


def _bits(rec: Recording) -> list[bytes]:
    return [rec.t.tobytes(), rec.thrust.tobytes(), rec.speed.tobytes(), rec.position.tobytes()]


def test_every_effect_block_is_covered() -> None:
    assert set(BLOCKS) == set(EFFECT_BLOCKS)


@pytest.mark.parametrize("name", list(_plants()))
def test_fast_simulation_is_the_reference_bit_for_bit(name: str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    plant = _plants()[name]
    seed = sorted(_plants()).index(name)
    fast = _recordings(plant, seed)
    with monkeypatch.context() as m:
        m.setattr(motor, "effect_function", _one_formula)
        m.setattr(motor, "Normals", _OneDrawAtATime)
        reference = _recordings(plant, seed)
    moved = [np.abs(r.speed).max() for r in reference]
    assert min(moved) > 1e-3, name  # the drive moves the axis in both runs
    for got, want in zip(fast, reference, strict=True):
        assert _bits(got) == _bits(want), name


def test_the_block_draws_are_the_single_draws() -> None:
    for seed in range(5):
        a = motor.Normals(np.random.default_rng(seed))
        b = np.random.default_rng(seed)
        got = [a.draw() for _ in range(3 * motor.NOISE_BLOCK + 5)]
        want = [float(b.standard_normal()) for _ in range(len(got))]
        assert got == want


@pytest.mark.parametrize("name", [n for n, p in _plants().items() if p.thrust_lag is None])
def test_unlagged_steps_are_the_general_step_bit_for_bit(name: str) -> None:
    sim = motor.MotorSimulator(_plants()[name], seed=0)
    rk4 = sim._rk4
    rng = np.random.default_rng(7)
    for _ in range(300):
        x, v, f, cmd, w = (float(a) for a in rng.normal(0.0, [0.01, 0.3, 20.0, 20.0, 1.0]))
        v = float(rng.choice([v, 0.0, -0.0, 1e-4 * v]))
        cmd = float(rng.choice([cmd, 0.0, -0.0]))
        steps = int(rng.integers(1, 9))
        got = rk4.run(x, v, f, steps * rk4.h_max, cmd, w)
        want = rk4._run_general(x, v, f, steps, steps * rk4.h_max / steps, cmd, w)
        assert np.array(got).tobytes() == np.array(want).tobytes(), name


@pytest.mark.parametrize("name", [n for n, p in _plants().items() if p.noise is None])
def test_replay_is_set_state_and_advance_per_sample(name: str) -> None:
    plant = _plants()[name]
    rec = motor.simulate(plant, _drive(3), seed=3)
    restart = list(range(0, N, 37))
    pos, spd = rec.position.tolist(), rec.speed.tolist()
    got = motor.MotorSimulator(plant, seed=0).replay(rec.thrust.tolist(), restart, pos, spd)
    sim, want = motor.MotorSimulator(plant, seed=0), ([], [])
    for k, u in enumerate(rec.thrust.tolist()):
        if k in restart:
            sim.set_state(pos[k], spd[k])
        want[0].append(sim.state.speed_mps)
        want[1].append(sim.state.position_m)
        sim.advance(u)
    assert np.array(got).tobytes() == np.array(want).tobytes(), name
