"""Thrust sensor noise (noise.thrust_std): the recorded thrust is the applied command plus
white noise; the motor itself moves with the command. This errors-in-variables case is what
makes a NARX fit on a single-tone test place a pole pair at the tone (the seed's 16.5 Hz)."""

from __future__ import annotations

import numpy as np

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import nominal_plant, plant_from_dict, plant_to_dict


def _plant(thrust_std: float) -> object:
    d = plant_to_dict(nominal_plant())
    d["noise"] = {"thrust_std": thrust_std}
    return plant_from_dict(d)


def test_recorded_thrust_is_command_plus_white_noise() -> None:
    u = make_excitation("prbs", 20000, 500.0, seed=3)
    rec = simulate(_plant(2.0), u, seed=7)
    e = rec.thrust - u
    assert abs(np.std(e) - 2.0) < 0.05
    assert abs(np.mean(e)) < 0.05
    r1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert abs(r1) < 0.03


def test_thrust_noise_does_not_move_the_motor_or_shift_other_streams() -> None:
    u = make_excitation("paper-speed", 3000, 500.0, seed=1)
    clean = simulate(nominal_plant(), u, seed=4)
    noisy = simulate(_plant(5.0), u, seed=4)
    np.testing.assert_array_equal(clean.speed, noisy.speed)
    np.testing.assert_array_equal(clean.position, noisy.position)
    np.testing.assert_array_equal(clean.thrust, u)
    assert not np.array_equal(noisy.thrust, u)
