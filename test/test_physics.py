"""Motor physics against independent truths: closed forms, scipy's ZOH discretisation and
``solve_ivp`` on an ODE written out here from the documented equations."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq
from scipy.signal import cont2discrete

from pmsm_sysid.core.errors import DataError, PlantError
from pmsm_sysid.core.physics.motor import (
    MotorSimulator,
    effective_substeps,
    effects_force,
    simulate,
    stiff_rate,
)
from pmsm_sysid.core.physics.plant import (
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
    electrical_lag,
    nominal_plant,
)

NOM = nominal_plant()
M, B, T = NOM.mass_kg, NOM.viscous_n_per_mps, 1.0 / NOM.sample_rate_hz
LAM = B / M


def prbs_like(n: int, seed: int = 1, amp: float = 20.0, hold: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(-amp, amp, n // hold + 1), hold)[:n]


# ------------------------------------------------------------------ linear closed forms


def test_step_response_is_first_order_closed_form() -> None:
    n, force = 500, 10.0
    rec = simulate(NOM, np.full(n, force))
    t = np.arange(n) * T
    v_exact = force / B * (1.0 - np.exp(-LAM * t))
    x_exact = force / B * (t - (1.0 - np.exp(-LAM * t)) / LAM)
    assert rec.speed[0] == 0.0 and rec.position[0] == 0.0  # y(k) depends on u(k-1) only
    np.testing.assert_allclose(rec.speed, v_exact, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.position, x_exact, rtol=0, atol=1e-12)


def test_discrete_pole_and_zoh_recursion() -> None:
    u = prbs_like(2000)
    v = simulate(NOM, u).speed
    a = math.exp(-LAM * T)
    b = (1.0 - a) / B
    np.testing.assert_allclose(v[1:], a * v[:-1] + b * u[:-1], rtol=0, atol=1e-13)
    theta, *_ = np.linalg.lstsq(np.column_stack([v[:-1], u[:-1]]), v[1:], rcond=None)
    assert theta[0] == pytest.approx(a, abs=1e-11)
    assert theta[1] == pytest.approx(b, abs=1e-13)


@pytest.mark.parametrize("tau", [0.0, 0.0016 / 3.8835, 2e-3])
def test_frequency_response_matches_scipy_zoh(tau: float) -> None:
    """Gain and phase of a sampled sine through the (lagged) motor = ZOH-discretised H(s)."""
    plant = NOM if tau == 0 else NOM.with_effects(thrust_lag=ThrustLag(tau))
    f_hz, amp, n_settle, n_fit = 40.0, 20.0, 1000, 1000   # 80 whole periods in the fit window
    k = np.arange(n_settle + n_fit)
    v = simulate(plant, amp * np.sin(2 * np.pi * f_hz * k * T)).speed[n_settle:]
    kk = k[n_settle:]
    basis = np.column_stack([np.sin(2 * np.pi * f_hz * kk * T), np.cos(2 * np.pi * f_hz * kk * T)])
    (s_coef, c_coef), *_ = np.linalg.lstsq(basis, v, rcond=None)
    measured = complex(s_coef, c_coef) / amp            # y = A|H| sin(wkT + arg H)
    den = np.polymul([M, B], [tau, 1.0]) if tau > 0 else np.array([M, B])
    num_d, den_d, _ = cont2discrete(([1.0], den), T, method="zoh")
    z = np.exp(1j * 2 * np.pi * f_hz * T)
    expected = np.polyval(np.ravel(num_d), z) / np.polyval(den_d, z)
    assert abs(measured) == pytest.approx(abs(expected), rel=2e-6)
    assert np.angle(measured) == pytest.approx(np.angle(expected), abs=2e-6)


def test_integer_transport_delay_shifts_by_exactly_delay() -> None:
    u = prbs_like(800)
    plain = simulate(NOM, u).speed
    delayed = simulate(NOM.with_effects(transport_delay=TransportDelay(3 * T)), u).speed
    np.testing.assert_array_equal(delayed[:3], 0.0)
    np.testing.assert_allclose(delayed[3:], plain[:-3], rtol=0, atol=1e-15)


def test_fractional_transport_delay_is_exact() -> None:
    u = prbs_like(800)
    m, r = 2, 0.4 * T
    v = simulate(NOM.with_effects(transport_delay=TransportDelay(m * T + r)), u).speed
    uu = np.concatenate([np.zeros(m + 1), u])  # uu[j + m + 1] = u[j], zeros before start
    a = math.exp(-LAM * T)
    b_old = math.exp(-LAM * (T - r)) * (1.0 - math.exp(-LAM * r)) / B
    b_new = (1.0 - math.exp(-LAM * (T - r))) / B
    k = np.arange(len(u) - 1)
    pred = a * v[:-1] + b_old * uu[k] + b_new * uu[k + 1]   # u(k-m-1), u(k-m)
    np.testing.assert_allclose(v[1:], pred, rtol=0, atol=1e-13)


def test_spring_steady_deflection_is_f_over_k() -> None:
    k_spring, force = 500.0, 10.0
    rec = simulate(NOM.with_effects(spring=Spring(k_spring)), np.full(3000, force))
    assert rec.position[-1] == pytest.approx(force / k_spring, abs=1e-10)
    assert abs(rec.speed[-1]) < 1e-10


def test_force_offset_sign_is_inverse_dynamics() -> None:
    """F = M a + B v + offset: with no command the axis settles at v = -offset/B."""
    rec = simulate(NOM.with_effects(force_offset=ForceOffset(2.0)), np.zeros(2000))
    assert rec.speed[-1] == pytest.approx(-2.0 / B, rel=1e-10)
    np.testing.assert_allclose(effects_force(NOM.with_effects(force_offset=ForceOffset(2.0)),
                                             [0.0, 1.0], [0.0, -3.0], 5.0), [2.0, 2.0])


# ------------------------------------------------------------------ friction


@pytest.mark.parametrize("viscous", [B, 0.0])
def test_coulomb_deceleration_closed_form(viscous: float) -> None:
    fc, v0 = 5.0, 0.5
    plant = replace(NOM, viscous_n_per_mps=viscous, coulomb_friction=CoulombFriction(fc))
    rec = simulate(plant, np.zeros(500), v0=v0)
    t = np.arange(500) * T
    if viscous > 0:
        lam = viscous / M
        t_stop = math.log(1.0 + viscous * v0 / fc) / lam
        v_exact = (v0 + fc / viscous) * np.exp(-lam * t) - fc / viscous
        x_stop = (v0 + fc / viscous) * (1 - math.exp(-lam * t_stop)) / lam - fc / viscous * t_stop
    else:
        t_stop = M * v0 / fc
        v_exact = v0 - fc / M * t
        x_stop = v0 * t_stop / 2
    moving = v_exact > 0.02  # beyond 20 smoothing scales tanh(v/vs) = 1 to 1e-17
    np.testing.assert_allclose(rec.speed[moving], v_exact[moving], rtol=0, atol=1e-10)
    stopped = t > t_stop + 0.05
    assert np.abs(rec.speed[stopped]).max() < 1e-9      # at rest, no reversal
    assert rec.position[-1] == pytest.approx(x_stop, abs=2e-6)


def test_tanh_regularised_sign_and_creep() -> None:
    """sign(v) = tanh(v/vs): 0 at rest, +-Fc beyond a few vs; under F < Fc it creeps."""
    fc, vs = 4.0, 1e-3
    plant = NOM.with_effects(coulomb_friction=CoulombFriction(fc, vs))
    v = np.array([-0.1, -10 * vs, 0.0, vs, 10 * vs, 0.1])
    np.testing.assert_allclose(effects_force(plant, 0.0, v, 0.0), fc * np.tanh(v / vs))
    assert effects_force(plant, 0.0, 0.0, 0.0)[()] == 0.0
    force = 2.0
    creep = brentq(lambda s: fc * math.tanh(s / vs) + B * s - force, 0.0, 1.0, xtol=1e-15)
    rec = simulate(plant, np.full(1000, force))
    assert rec.speed[-1] == pytest.approx(creep, rel=1e-8)
    assert creep < vs  # well below a mm/s: the regularised model "sticks" to within vs


def test_stribeck_formula_and_breakaway() -> None:
    plant = NOM.with_effects(coulomb_friction=CoulombFriction(2.0),
                             stribeck_friction=StribeckFriction(1.5, 0.02))
    v = np.array([-0.2, -0.02, -0.005, 0.005, 0.02, 0.2])
    want = (2.0 + 1.5 * np.exp(-(v / 0.02) ** 2)) * np.tanh(v / 1e-3)
    np.testing.assert_allclose(effects_force(plant, 0.0, v, 0.0), want)
    # steady speed under a constant push solves F = B v + friction(v) of the smoothed model:
    # below the breakaway level 3.5 N it creeps at about a smoothing scale, above it slides
    def friction(s: float) -> float:
        return (2.0 + 1.5 * math.exp(-(s / 0.02) ** 2)) * math.tanh(s / 1e-3)

    for force in (3.0, 4.0):
        v_ss = brentq(lambda s, f=force: B * s + friction(s) - f, 0.0, 1.0, xtol=1e-15)
        rec = simulate(plant, np.full(1500, force))
        assert rec.speed[-1] == pytest.approx(v_ss, rel=1e-8)
        assert (v_ss < 2e-3) == (force < 3.5)


# ------------------------------------------------------------------ position-periodic forces


def test_cogging_is_periodic_in_x_with_its_pitch() -> None:
    cog = Cogging(3.0, 0.005, 0.5, (Harmonic(2, 1.0, 0.3),))
    plant = NOM.with_effects(cogging=cog)
    x = np.linspace(-0.02, 0.02, 401)
    f = effects_force(plant, x, 0.0, 0.0)
    want = 3.0 * np.sin(2 * np.pi * x / 0.005 + 0.5) + 1.0 * np.sin(4 * np.pi * x / 0.005 + 0.3)
    np.testing.assert_allclose(f, want, atol=1e-12)
    np.testing.assert_allclose(effects_force(plant, x + 0.005, 0.0, 0.0), f, atol=1e-11)
    assert np.abs(effects_force(plant, x + 0.0025, 0.0, 0.0) - f).max() > 1.0
    assert np.abs(f).max() > 3.0


def test_cogging_static_equilibrium() -> None:
    """A steady push F < A settles where A sin(2 pi x/p) = F (sign of F_effects)."""
    pitch, amp, force = 0.01, 3.0, 1.5
    rec = simulate(NOM.with_effects(cogging=Cogging(amp, pitch)), np.full(2000, force))
    assert rec.position[-1] == pytest.approx(pitch / (2 * np.pi) * math.asin(force / amp),
                                             abs=1e-9)


def test_thrust_ripple_gain_equilibrium() -> None:
    """Spring + ripple: x* solves F (1 + r sin(2 pi x/p)) = k x."""
    k_spring, force, rel, pitch = 400.0, 8.0, 0.2, 0.03
    plant = NOM.with_effects(spring=Spring(k_spring), thrust_ripple=ThrustRipple(rel, pitch))
    x_star = brentq(lambda x: force * (1 + rel * math.sin(2 * math.pi * x / pitch))
                    - k_spring * x, 0.0, 0.1, xtol=1e-15)
    rec = simulate(plant, np.full(3000, force))
    assert rec.position[-1] == pytest.approx(x_star, abs=1e-9)
    assert abs(x_star - force / k_spring) > 1e-3  # the ripple matters here
    f = effects_force(plant, [0.0075, 0.0], 0.0, 10.0)  # sin = 1 at x = p/4
    np.testing.assert_allclose(f, [-rel * 10.0 + k_spring * 0.0075, 0.0], atol=1e-12)


# ------------------------------------------------------------------ RK4 against solve_ivp

COG = Cogging(3.0, 0.005, 0.5, (Harmonic(2, 1.0, 0.3),))
EFFECT_CASES = {
    "nominal": {},
    "thrust_lag": {"thrust_lag": electrical_lag(NOM)},
    "coulomb": {"coulomb_friction": CoulombFriction(4.0)},
    "stribeck": {"coulomb_friction": CoulombFriction(1.0),
                 "stribeck_friction": StribeckFriction(1.5, 0.02)},
    "cogging": {"cogging": COG},
    "ripple_spring": {"thrust_ripple": ThrustRipple(0.05, 0.032, 0.2), "spring": Spring(50.0)},
    "all": {"cogging": COG, "coulomb_friction": CoulombFriction(4.0),
            "stribeck_friction": StribeckFriction(1.5, 0.02), "force_offset": ForceOffset(0.7),
            "thrust_ripple": ThrustRipple(0.05, 0.032, 0.2), "thrust_lag": electrical_lag(NOM),
            "spring": Spring(50.0)},
}


def reference_rhs(plant: Plant):
    """The documented ODE, state (x, v, F), for solve_ivp."""
    m, b = plant.mass_kg, plant.viscous_n_per_mps

    def rhs(_t: float, s: np.ndarray, u: float) -> list[float]:
        x, v, f = s
        lag = plant.thrust_lag
        df = (u - f) / lag.tau_s if lag is not None else 0.0
        force = f if lag is not None else u
        if plant.thrust_ripple is not None:
            rp = plant.thrust_ripple
            force *= 1 + rp.relative * math.sin(2 * math.pi * x / rp.pitch_m + rp.phase_rad)
        eff = 0.0
        if plant.cogging is not None:
            c = plant.cogging
            eff += c.amplitude_n * math.sin(2 * math.pi * x / c.pitch_m + c.phase_rad)
            for h in c.harmonics:
                eff += h.amplitude_n * math.sin(2 * math.pi * h.order * x / c.pitch_m
                                                + h.phase_rad)
        if plant.coulomb_friction is not None:
            cf = plant.coulomb_friction
            eff += cf.amplitude_n * math.tanh(v / cf.smoothing_mps)
        if plant.stribeck_friction is not None:
            sf = plant.stribeck_friction
            eff += (sf.static_n * math.exp(-(v / sf.velocity_mps) ** 2)
                    * math.tanh(v / sf.smoothing_mps))
        if plant.force_offset is not None:
            eff += plant.force_offset.amplitude_n
        if plant.spring is not None:
            eff += plant.spring.stiffness_n_per_m * x
        return [v, (force - b * v - eff) / m, df]
    return rhs


def reference_step(plant: Plant, state: np.ndarray, u: float) -> np.ndarray:
    sol = solve_ivp(reference_rhs(plant), (0.0, T), state, args=(u,), method="DOP853",
                    rtol=1e-12, atol=1e-14)
    return np.asarray(sol.y[:, -1])


def input_mixture() -> np.ndarray:
    n = 300
    return 40 * np.sin(2 * np.pi * 16.5 * np.arange(n) * T) + prbs_like(n, seed=3, amp=10,
                                                                         hold=50)


@pytest.mark.parametrize("case", list(EFFECT_CASES))
def test_rk4_matches_solve_ivp(case: str) -> None:
    """Whole-trajectory agreement over 300 samples (0.6 s, about 10 velocity reversals)."""
    plant = NOM.with_effects(**EFFECT_CASES[case])
    u = input_mixture()
    rec = simulate(plant, u)
    state = np.zeros(3)
    ref_v, ref_x = [0.0], [0.0]
    for k in range(len(u) - 1):
        state = reference_step(plant, state, u[k])
        ref_x.append(state[0])
        ref_v.append(state[1])
    signs = np.sign(rec.speed).tolist()
    assert signs.count(1.0) > 50 and signs.count(-1.0) > 50, case  # both signs visited
    np.testing.assert_allclose(rec.speed, ref_v, rtol=0, atol=2e-7)
    np.testing.assert_allclose(rec.position, ref_x, rtol=0, atol=1e-8)


def test_rk4_one_sample_local_error_with_all_effects() -> None:
    """From the reference state, one simulator sample agrees with solve_ivp to < 1e-7 m/s."""
    plant = NOM.with_effects(**EFFECT_CASES["all"])
    u = input_mixture()
    state = np.zeros(3)
    worst = 0.0
    for k in range(len(u) - 1):
        sim = MotorSimulator(plant)
        sim.set_state(state[0], state[1], state[2])
        sim.advance(u[k])
        state = reference_step(plant, state, u[k])
        got = sim.state
        worst = max(worst, abs(got.speed_mps - state[1]), abs(got.force_n - state[2]) * 1e-4)
    assert worst < 1e-7


def test_stiff_friction_raises_substeps_and_stays_accurate() -> None:
    plant = NOM.with_effects(coulomb_friction=CoulombFriction(40.0))
    n_sub = effective_substeps(plant)
    assert n_sub * 1.0 >= T * stiff_rate(plant) > NOM.substeps   # h * lambda <= 1
    u = 60 * np.sin(2 * np.pi * 5 * np.arange(200) * T)
    rec = simulate(plant, u)
    state = np.zeros(3)
    for k in range(len(u) - 1):
        state = reference_step(plant, state, u[k])
        assert rec.speed[k + 1] == pytest.approx(state[1], abs=1e-6)
    assert effective_substeps(NOM) == NOM.substeps == 8


@pytest.mark.parametrize("tau", [1e-8, 1e-5, 1e-4])
def test_lags_shorter_than_a_step_match_the_closed_form(tau: float) -> None:
    """Linear lag + mass-damper: the ZOH recursion of the 2-state system, from scipy."""
    u = prbs_like(500)
    v = simulate(NOM.with_effects(thrust_lag=ThrustLag(tau)), u).speed
    a_c = np.array([[-LAM, 1.0 / M], [0.0, -1.0 / tau]])
    a_d, b_d, *_ = cont2discrete((a_c, np.array([[0.0], [1.0 / tau]]), np.eye(2),
                                  np.zeros((2, 1))), T, method="zoh")
    s = np.zeros(2)
    ref = []
    for uk in u:
        ref.append(s[0])
        s = a_d @ s + b_d[:, 0] * uk
    np.testing.assert_allclose(v, ref, rtol=0, atol=1e-9)
    plain = simulate(NOM, u).speed
    assert np.abs(v - plain).max() < 30 * tau  # the lag's whole effect is O(tau)


# ------------------------------------------------------------------ noise, seeds, run time


def test_measurement_noise_statistics() -> None:
    plant = NOM.with_effects(noise=Noise(speed_std=0.01, position_std=1e-4))
    rec = simulate(plant, np.zeros(20000), seed=5)
    for sig, std in ((rec.speed, 0.01), (rec.position, 1e-4)):
        assert np.std(sig) == pytest.approx(std, rel=0.03)
        assert abs(np.corrcoef(sig[1:], sig[:-1])[0, 1]) < 4 / math.sqrt(len(sig))
    assert abs(np.corrcoef(rec.speed, rec.position)[0, 1]) < 4 / math.sqrt(len(rec.speed))


def test_process_force_is_white_equation_error() -> None:
    """With force_std only, v(k+1) - a v(k) - b u(k) = b w(k): white, std b*force_std."""
    plant = NOM.with_effects(noise=Noise(force_std=2.0))
    u = prbs_like(20000)
    v = simulate(plant, u, seed=9).speed
    a = math.exp(-LAM * T)
    b = (1 - a) / B
    e = v[1:] - a * v[:-1] - b * u[:-1]
    assert np.std(e) == pytest.approx(b * 2.0, rel=0.03)
    assert abs(np.corrcoef(e[1:], e[:-1])[0, 1]) < 4 / math.sqrt(len(e))
    assert abs(np.corrcoef(e, u[:-1])[0, 1]) < 4 / math.sqrt(len(e))


def test_seeded_and_deterministic() -> None:
    plant = NOM.with_effects(noise=Noise(0.002, 5e-6, 1.0), cogging=COG)
    u = prbs_like(1000)
    a, b = simulate(plant, u, seed=1), simulate(plant, u, seed=1)
    np.testing.assert_array_equal(a.speed, b.speed)
    np.testing.assert_array_equal(a.position, b.position)
    assert not np.array_equal(a.speed, simulate(plant, u, seed=2).speed)
    # the measurement-noise stream does not depend on which effects are on
    quiet = NOM.with_effects(noise=Noise(0.002, 0.0, 0.0))
    noisy_cog = quiet.with_effects(cogging=COG)
    d1 = simulate(quiet, u, seed=4).speed - simulate(NOM, u).speed
    d2 = simulate(noisy_cog, u, seed=4).speed - simulate(NOM.with_effects(cogging=COG), u).speed
    np.testing.assert_allclose(d1, d2, atol=1e-15)


def test_step_by_step_equals_simulate_and_set_plant_keeps_state() -> None:
    plant = NOM.with_effects(noise=Noise(0.002, 5e-6, 1.0))
    u = prbs_like(600)
    rec = simulate(plant, u, seed=3)
    sim = MotorSimulator(plant, seed=3)
    out = []
    for k in range(len(u)):
        out.append(sim.measure())
        assert sim.measure() == out[-1]  # measuring twice draws nothing
        if k == 300:
            sim.set_plant(plant)  # same parameters: bit-for-bit unchanged
        sim.advance(u[k])
    np.testing.assert_array_equal(np.array(out), np.column_stack([rec.speed, rec.position]))
    assert sim.time_s == pytest.approx(600 * T) and sim.sample_index == 600

    # switch cogging on at run time: state continuous, trajectory then departs
    sim = MotorSimulator(plant, seed=3)
    for k in range(300):
        sim.advance(u[k])
    before = sim.state
    sim.set_plant(plant.with_effects(cogging=COG))
    assert sim.state == before
    speeds = []
    for k in range(300, 600):
        speeds.append(sim.measure()[0])
        sim.advance(u[k])
    assert speeds[0] == rec.speed[300]
    assert np.abs(np.array(speeds) - rec.speed[300:]).max() > 1e-3
    with pytest.raises(PlantError, match="sample rate cannot change"):
        sim.set_plant(replace(plant, sample_rate_hz=1000.0))


def test_quantisation() -> None:
    plant = NOM.with_effects(quantisation=Quantisation(position_m=1e-5, speed_mps=1e-3),
                             noise=Noise(1e-3, 1e-6, 0.0))
    rec = simulate(plant, prbs_like(1000))
    np.testing.assert_allclose(rec.position / 1e-5, np.round(rec.position / 1e-5), atol=1e-6)
    np.testing.assert_allclose(rec.speed / 1e-3, np.round(rec.speed / 1e-3), atol=1e-6)
    assert len(np.unique(rec.speed)) > 20


def test_bad_inputs() -> None:
    with pytest.raises(DataError, match="not finite"):
        MotorSimulator(NOM).advance(float("nan"))
    with pytest.raises(DataError, match="non-finite"):
        simulate(NOM, np.array([0.0, np.inf]))
    with pytest.raises(DataError, match="1-D"):
        simulate(NOM, np.zeros((2, 2)))
    with pytest.raises(PlantError, match="finite"):
        MotorSimulator(NOM, x0=float("nan"))
    with pytest.raises(PlantError, match="too stiff to simulate"):
        MotorSimulator(NOM.with_effects(coulomb_friction=CoulombFriction(500.0, 1e-6)))
    with pytest.raises(PlantError, match="<= 4096"):
        replace(NOM, substeps=10**6)


def test_effects_force_broadcasts() -> None:
    plant = NOM.with_effects(cogging=COG, coulomb_friction=CoulombFriction(2.0))
    out = effects_force(plant, np.zeros((3, 1)), np.linspace(-1, 1, 4), 1.0)
    assert out.shape == (3, 4)
    assert effects_force(NOM, [1.0, 2.0], 0.0, 0.0).tolist() == [0.0, 0.0]


@settings(max_examples=20, deadline=None)
@given(mass=st.floats(0.1, 50.0), viscous=st.just(0.0) | st.floats(1e-3, 500.0),
       substeps=st.integers(1, 12),
       seed=st.integers(0, 2**16))
def test_linear_plants_follow_the_zoh_recursion(mass: float, viscous: float, substeps: int,
                                                seed: int) -> None:
    """Any mass-damper: v(k+1) = a v(k) + b u(k), a = exp(-BT/M), b = (1-a)/B (T/M if B=0)."""
    plant = replace(NOM, mass_kg=mass, viscous_n_per_mps=viscous, substeps=substeps)
    u = prbs_like(300, seed=seed)
    v = simulate(plant, u).speed
    a = math.exp(-viscous * T / mass)
    b = -math.expm1(-viscous * T / mass) / viscous if viscous > 0 else T / mass
    scale = np.abs(v).max() + 1e-12
    hl = viscous / mass * T / max(substeps, effective_substeps(plant))
    tol = max(1e-12, 0.05 * hl**5) * scale * 300   # RK4 local error (h lambda)^5/120
    np.testing.assert_allclose(v[1:], a * v[:-1] + b * u[:-1], rtol=0, atol=tol)


def test_delay_switched_on_at_run_time_uses_the_command_history() -> None:
    u = prbs_like(600)
    sim = MotorSimulator(NOM)
    v = []
    for k in range(600):
        if k == 300:
            sim.set_plant(NOM.with_effects(transport_delay=TransportDelay(3 * T)))
        v.append(sim.measure()[0])
        sim.advance(u[k])
    va = np.array(v)
    a = math.exp(-LAM * T)
    b = (1 - a) / B
    np.testing.assert_allclose(va[1:301], a * va[:300] + b * u[:300], rtol=0, atol=1e-13)
    np.testing.assert_allclose(va[301:], a * va[300:-1] + b * u[297:-4], rtol=0, atol=1e-13)
