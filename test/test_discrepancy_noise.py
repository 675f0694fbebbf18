"""Noise is not physics: process force, sensor noise under feedback, the input's own lines.

Errors in variables (a noisy acceleration; a process force in the same interval as the
acceleration it causes) used to be taken for a mass change, and a periodic input's own
spectral lines for an unexplained force. Each fix has a control with nothing wrong and a
recording where a real effect hides under the same noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.physics.closed_loop import (
    PositionLoop,
    reference_trajectory,
    run_closed_loop,
)
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import Noise, Quantisation, nominal_plant

FS = 500.0
N = 2500
FAST = DiagnoseOptions(replay=False, gfrf=False)
HIGH = Noise(speed_std=0.005, position_std=1e-5, force_std=1.5)
QUANT = Quantisation(position_m=1e-6)


def _open(kind: str, seed: int, noise: Noise, mass: float | None = None):  # type: ignore[no-untyped-def]
    plant = nominal_plant().with_effects(noise=noise, quantisation=QUANT)
    if mass is not None:
        plant = plant.with_effects(mass_kg=mass)
    return simulate(plant, make_excitation(kind, N, FS, seed=seed), seed=seed)


def _closed(seed: int, noise: Noise):  # type: ignore[no-untyped-def]
    plant = nominal_plant().with_effects(noise=noise, quantisation=QUANT)
    ref = reference_trajectory(N, FS, (0.02, 0.004), (0.4, 1.7))
    return run_closed_loop(plant, ref, PositionLoop.for_bandwidth(nominal_plant(), 15.0),
                           seed=seed)


@pytest.mark.parametrize("kind", ["multisine", "chirp"])
def test_white_process_force_is_not_a_mass_error(kind: str) -> None:
    noise = Noise(speed_std=0.001, position_std=2e-6, force_std=4.0)
    result = diagnose(nominal_plant(), _open(kind, 3, noise), _open(kind, 4, noise), FAST)
    assert result.effects == ()


def test_sensor_noise_under_feedback_is_not_a_mass_error() -> None:
    result = diagnose(nominal_plant(), _closed(5, HIGH), _closed(6, HIGH), FAST)
    assert result.effects == ()


def test_mass_error_under_high_noise_with_a_chirp() -> None:
    """13 % more mass, 5 mm/s speed noise, 1.5 N process force: the mass within 3 %."""
    true_mass = 1.13 * nominal_plant().mass_kg
    est = _open("chirp", 7, HIGH, true_mass)
    val = _open("chirp", 8, HIGH, true_mass)
    result = diagnose(nominal_plant(), est, val, FAST)
    named = {e.name: e for e in result.effects}
    assert set(named) == {"mass_error"}
    assert named["mass_error"].params["mass_kg"] == pytest.approx(true_mass, rel=0.03)
    assert named["mass_error"].confidence == "high"
    fit = result.fit["validation"]
    assert fit["nrmse_after"] < 0.9 * fit["nrmse_before"]


def test_a_binary_prbs_lines_are_the_inputs_not_the_plants() -> None:
    """A PRBS of a short period has spectral lines; on a nominal plant none may be reported."""
    noise = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0)
    for seed in (1, 2):
        rec = _open("prbs", seed, noise)
        result = diagnose(nominal_plant(), rec, _open("prbs", seed + 10, noise), FAST)
        assert result.effects == (), seed
        line = next(w for w in result.where if w.axis == "frequency")
        assert line.significance < 3.0
    assert np.isfinite(line.details["line_to_local_level"])


@pytest.mark.parametrize("kind", ["prbs", "aprbs"])
def test_one_ms_actuator_lag_with_random_binary_inputs(kind: str) -> None:
    """A held random input is strongly autocorrelated and the motion answers it at once:
    that is no feedback. The 1 ms lag is named (not a delay, not a mass/viscous change)."""
    from pmsm_sysid.core.physics.plant import ThrustLag
    from pmsm_sysid.core.plantfit.feedback import FEEDBACK_Z, feedback_z

    noise = Noise(speed_std=0.001, position_std=2e-6, force_std=0.3)
    plant = nominal_plant().with_effects(noise=noise, quantisation=QUANT,
                                         thrust_lag=ThrustLag(0.001))
    recs = [simulate(plant, make_excitation(kind, N, FS, seed=s), seed=s) for s in (1, 2)]
    assert feedback_z(recs[0]) < FEEDBACK_Z
    result = diagnose(nominal_plant(), recs[0], recs[1], FAST)
    named = {e.name: e for e in result.effects}
    assert set(named) == {"thrust_lag"}, list(named)
    assert named["thrust_lag"].params["tau_s"] == pytest.approx(0.001, rel=0.3)
    assert not result.method["feedback"]["closed_loop"]


def test_thrust_sensor_noise_is_not_feedback() -> None:
    """Open loop with 5 N of thrust-sensor noise (the paper bags' noise): not a loop."""
    from pmsm_sysid.core.plantfit.feedback import FEEDBACK_Z, feedback_z

    noise = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0, thrust_std=5.0)
    for seed in (1, 2, 3):
        rec = simulate(nominal_plant().with_effects(noise=noise),
                       make_excitation("paper-speed", 4500, FS, seed=seed), seed=seed)
        assert feedback_z(rec) < FEEDBACK_Z, seed
    assert feedback_z(_closed(5, HIGH)) > 3 * FEEDBACK_Z
