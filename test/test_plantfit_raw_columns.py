"""The position-periodic effects' raw columns (one phase per harmonic, written in place)
are what the plain formula gives, bit for bit and in the same memory layout: the columns
of sin and cos of the phase, each times the travel gain, stacked side by side -- also when
a column is made from the gain and phases another column of the same pitch left."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.plantfit import kinematics
from pmsm_sysid.core.plantfit.averaging import travel_gain
from pmsm_sysid.core.plantfit.kinematics import EquationData, equation_data
from pmsm_sysid.core.plantfit.library import (
    Effect,
    Phases,
    families,
    family_chunks,
    family_columns,
    raw_columns,
)
from pmsm_sysid.core.plantfit.select import Candidates


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
    kept: Phases = {}  # a ripple column from the phases its cogging pitch left, and alone
    for e in members + sorted(members, key=lambda e: (e.pitch_m, e.name)):
        got, want = raw_columns(e, data, kept), _plain(e, data)
        assert got.shape == want.shape and got.dtype == want.dtype, e.label()
        assert got.flags.c_contiguous and want.flags.c_contiguous, e.label()
        assert got.tobytes() == want.tobytes(), e.label()
        assert raw_columns(e, data).tobytes() == want.tobytes(), e.label()
    assert len(kept) > len(members) // 2


def test_candidates_built_side_by_side_are_each_familys_own_columns() -> None:
    """Cogging and ripple built a chunk of each in turn (sharing their pitches' phases)
    hold what each family's columns are alone, and the same Grams."""
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 3000, 500.0, seed=5), seed=1)
    data = equation_data(plant, rec)
    kinematics.PROJECTED.clear()  # computed here, not served from an earlier test
    cands = Candidates.build(data)
    names = [f.name for f in cands.families]
    assert {"cogging", "thrust_ripple"} <= set(names)
    kinematics.PROJECTED.clear()
    for i, fam in enumerate(cands.families):
        alone = family_columns(fam, data)
        assert cands.cols[i].tobytes() == alone.astype(np.float32).tobytes(), fam.name
        gram = np.concatenate([np.einsum("knm,knp->kmp", c, c)  # a chunk at a time
                               for _, c in family_chunks(fam, data)])
        assert cands.grams[i].tobytes() == gram.tobytes(), fam.name
