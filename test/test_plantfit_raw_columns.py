"""The position-periodic effects' raw columns (one phase per harmonic, written in place)
are what the plain formula gives, bit for bit and in the same memory layout: the columns
of sin and cos of the phase, each times the travel gain, stacked side by side."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.plantfit.averaging import travel_gain
from pmsm_sysid.core.plantfit.kinematics import EquationData, equation_data
from pmsm_sysid.core.plantfit.library import Effect, families, raw_columns


def _plain(e: Effect, data: EquationData) -> np.ndarray:
    x = data.x
    k = 2.0 * math.pi / e.pitch_m
    if e.name == "cogging":
        cols = []
        for h in e.orders:
            g = travel_gain(data.v, data.period, h / e.pitch_m, data.mode)
            cols += [g * np.sin(h * k * x), g * np.cos(h * k * x)]
        return np.column_stack(cols)
    g = travel_gain(data.v, data.period, 1.0 / e.pitch_m, data.mode) * data.regressor_force
    return np.column_stack([g * np.sin(k * x), g * np.cos(k * x)])


@pytest.mark.parametrize(("excitation", "noisy_reading"),
                         [("paper-position", False), ("paper-position", True),
                          ("paper-speed", False)])
def test_periodic_raw_columns_are_the_plain_formula_bit_for_bit(
        excitation: str, noisy_reading: bool) -> None:
    plant = nominal_plant()
    rec = simulate(plant, make_excitation(excitation, 3000, 500.0, seed=2), seed=0)
    data = equation_data(plant, rec, thrust_gap=3 if noisy_reading else 0)
    members = [e for f in families(data) if f.name in ("cogging", "thrust_ripple")
               for e in f.members]
    assert {e.name for e in members} == {"cogging", "thrust_ripple"}
    cog = next(e for e in members if e.name == "cogging")
    members += [dataclasses.replace(cog, orders=(1, 2, 3)), dataclasses.replace(cog, orders=(2, 5))]
    for e in members:
        got, want = raw_columns(e, data), _plain(e, data)
        assert got.shape == want.shape and got.dtype == want.dtype, e.label()
        assert got.flags.c_contiguous and want.flags.c_contiguous, e.label()
        assert got.tobytes() == want.tobytes(), e.label()
