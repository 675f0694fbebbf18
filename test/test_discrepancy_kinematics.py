"""Equation-error data: checked against the simulator, closed forms and numerical integrals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pmsm_sysid.core.physics.closed_loop import (
    PositionLoop,
    reference_trajectory,
    run_closed_loop,
)
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import effects_force, simulate
from pmsm_sysid.core.physics.plant import (
    CoulombFriction,
    Noise,
    Plant,
    Spring,
    ThrustLag,
    TransportDelay,
    nominal_plant,
)
from pmsm_sysid.core.plantfit.averaging import interval_force, interval_friction
from pmsm_sysid.core.plantfit.feedback import feedback_z
from pmsm_sysid.core.plantfit.kinematics import (
    choose_filter,
    equation_data,
    smoothed_speed_noise,
)
from pmsm_sysid.core.plantfit.library import Effect, columns
from pmsm_sysid.core.recording.signals import Recording

FS = 500.0


def _thrust(n: int = 2000, seed: int = 1) -> np.ndarray:
    return make_excitation("paper-position", n, FS, seed=seed)


def _lag_reference(cmd: np.ndarray, period: float, tau: float, delay: float,
                   steps: int = 400) -> np.ndarray:
    """Interval means by brute force: fine exponential-Euler steps of tau dF/dt = c - F."""
    h = period / steps
    z = cmd[0]
    out = np.empty(len(cmd))
    for k in range(len(cmd)):
        acc = 0.0
        for j in range(steps):
            t = k * period + (j + 0.5) * h - delay
            c = cmd[min(max(math.floor(t / period), 0), len(cmd) - 1)] if t >= 0 else cmd[0]
            z = c + (z - c) * math.exp(-h / tau) if tau > 0 else c
            acc += z
        out[k] = acc / steps
    return out


@pytest.mark.parametrize(("tau", "delay"), [(0.0, 0.0), (0.0, 0.0007), (0.0, 0.0031),
                                             (0.0004, 0.0), (0.003, 0.0013)])
def test_interval_force_matches_brute_force_integration(tau: float, delay: float) -> None:
    rng = np.random.default_rng(3)
    cmd = rng.normal(0, 10, 60)
    period = 0.002
    got = interval_force(cmd, period, tau, delay)
    want = _lag_reference(cmd, period, tau, delay)
    assert np.max(np.abs(got[5:] - want[5:])) < 2e-3 * np.max(np.abs(cmd))


def test_interval_force_fractional_delay_closed_form() -> None:
    cmd = np.array([1.0, 5.0, -2.0, 3.0])
    got = interval_force(cmd, 1.0, 0.0, 0.25)
    # the command in force switches a quarter period late: 1/4 of the old, 3/4 of the new
    assert got[1:] == pytest.approx(0.25 * cmd[:-1] + 0.75 * cmd[1:])


def test_nominal_noise_free_residual_is_zero_in_both_modes() -> None:
    """Exact ZOH inversion: the simulator (RK4) and the equation error agree to 1e-6 N."""
    plant = nominal_plant()
    rec = simulate(plant, _thrust(), seed=0)
    d = equation_data(plant, rec)
    assert d.mode == "speed"
    assert np.max(np.abs(d.y)) < 1e-6 * np.max(np.abs(rec.thrust))
    pos = equation_data(plant, rec, mode="position")
    # position-only pairing is second order in B T / M: small but not zero
    assert np.std(pos.y) < 2e-3 * np.std(rec.thrust)


def test_residual_is_the_missing_force() -> None:
    """Coulomb friction left out of the plant: the residual regresses on sign(v) with Fc."""
    truth = nominal_plant().with_effects(coulomb_friction=CoulombFriction(2.0))
    rec = simulate(truth, _thrust(), seed=0)
    d = equation_data(nominal_plant(), rec)
    beta = np.linalg.lstsq(columns(Effect("coulomb_friction"), d), d.y, rcond=None)[0]
    assert beta[0] == pytest.approx(2.0, rel=0.02)
    # and a plant that already holds the effect leaves (almost) nothing
    assert np.std(equation_data(truth, rec).y) < 0.02 * np.std(d.y)


@pytest.mark.parametrize("block", [ThrustLag(0.0008), TransportDelay(0.003)])
def test_dynamic_effects_in_the_plant_are_inverted_exactly(block: object) -> None:
    name = "thrust_lag" if isinstance(block, ThrustLag) else "transport_delay"
    truth = nominal_plant().with_effects(**{name: block})
    rec = simulate(truth, _thrust(), seed=0)
    # the viscous term sees the force vary within an interval: O(B T / M) of that variation
    assert np.max(np.abs(equation_data(truth, rec).y)) < 1e-3 * np.max(np.abs(rec.thrust))
    assert np.std(equation_data(nominal_plant(), rec).y) > 0.3


def test_spring_residual_matches_effects_force() -> None:
    truth = nominal_plant().with_effects(spring=Spring(80.0))
    rec = simulate(truth, _thrust(), seed=0)
    d = equation_data(nominal_plant(), rec)
    want = d.project(effects_force(truth, d.x, d.v, d.force))
    assert np.max(np.abs(d.y - want)) < 0.01 * np.max(np.abs(want))


def test_filter_band_follows_the_speed() -> None:
    t = np.arange(5000) / FS
    spec = choose_filter(np.sin(2 * np.pi * 12.0 * t), FS)
    assert spec.band_hz == pytest.approx(12.0, abs=0.2)
    assert spec.cutoff_hz == pytest.approx(48.0, abs=1.0)
    assert spec.decimation == 4  # floor(500 / (2.5 * 48))
    slow = choose_filter(np.sin(2 * np.pi * 0.5 * t), FS)
    assert slow.cutoff_hz == pytest.approx(0.05 * FS)  # the floor


def test_interval_friction_is_the_mean_over_a_linear_speed_ramp() -> None:
    eps = 1e-3
    for v0, v1, vs in [(-0.004, 0.003, 0.0), (0.002, 0.0021, 0.0), (-0.01, 0.02, 0.01),
                       (0.05, 0.049, 0.01)]:
        def g(s: float, v0: float = v0, v1: float = v1, vs: float = vs) -> float:
            v = v0 + (v1 - v0) * s
            hump = math.exp(-((v / vs) ** 2)) if vs > 0 else 1.0
            return hump * math.tanh(v / eps)
        want = quad(g, 0.0, 1.0, points=[0.5])[0]
        got = interval_friction(np.array([v0]), np.array([v1]), eps, vs)[0]
        # Stribeck's antiderivative uses |v| rounded by eps: exact up to O(eps / vs)
        assert got == pytest.approx(want, abs=0.002 if vs == 0 else 0.06)


def test_speed_noise_estimate() -> None:
    rng = np.random.default_rng(0)
    n = 4000
    t = np.arange(n) / FS
    speed = 0.1 * np.sin(2 * np.pi * 3 * t) + rng.normal(0, 0.002, n)
    rec = Recording(t=t, thrust=np.sin(t), speed=speed, position=np.cumsum(speed) / FS,
                    sample_rate_hz=FS)
    from scipy.signal import butter, sosfiltfilt
    sos = np.asarray(butter(4, 40.0, fs=FS, output="sos"))
    got = smoothed_speed_noise(rec, "speed", sos)
    imp = np.zeros(4001)
    imp[2000] = 1.0
    want = 0.002 * np.linalg.norm(sosfiltfilt(sos, 0.5 * (imp[1:] + imp[:-1])))
    assert got == pytest.approx(want, rel=0.1)


def test_feedback_is_detected_only_under_a_loop() -> None:
    noisy = nominal_plant().with_effects(noise=Noise(0.002, 5e-6, 1.0))
    open_loop = simulate(noisy, _thrust(2500), seed=2)
    ref = reference_trajectory(2500, FS, (0.02,), (0.5,))
    closed = run_closed_loop(noisy, ref, PositionLoop.for_bandwidth(noisy, 15.0), seed=2)
    assert feedback_z(open_loop) < 5.0
    assert feedback_z(closed) > 10.0
    # the loop tracks: position error well below the travel
    assert np.std(closed.position - ref) < 0.02 * np.ptp(ref)


def test_plant_rate_does_not_matter_only_the_data_rate() -> None:
    rec = simulate(nominal_plant(), _thrust(), seed=0)
    other = Plant(sample_rate_hz=1000.0)
    assert np.max(np.abs(equation_data(other, rec).y)) < 1e-6 * np.max(np.abs(rec.thrust))
