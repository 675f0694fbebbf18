"""Each library effect, left out of the plant, is named with its parameters; ERR is Eq. 4."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.discrepancy import diagnose
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import (
    Cogging,
    CoulombFriction,
    ForceOffset,
    Harmonic,
    Noise,
    Spring,
    ThrustLag,
    ThrustRipple,
    TransportDelay,
    nominal_plant,
    plant_from_dict,
)
from pmsm_sysid.core.plantfit.kinematics import equation_data
from pmsm_sysid.core.plantfit.library import Effect, columns
from pmsm_sysid.core.plantfit.select import Candidates, _family_err

NOISE = Noise(speed_std=0.002, position_std=5e-6, force_std=0.5)
THRUST = make_excitation("paper-position", 2500, 500.0, seed=1)

# (blocks added to the true plant, expected effect name, {param: (value, rel. tolerance)})
CASES: list[tuple[dict[str, Any], str, dict[str, tuple[float, float]]]] = [
    ({"force_offset": ForceOffset(-0.8)}, "force_offset", {"amplitude_n": (-0.8, 0.05)}),
    ({"coulomb_friction": CoulombFriction(2.0)}, "coulomb_friction",
     {"amplitude_n": (2.0, 0.05)}),
    ({"spring": Spring(50.0)}, "spring", {"stiffness_n_per_m": (50.0, 0.05)}),
    ({"mass_kg": 2.5}, "mass_error", {"mass_kg": (2.5, 0.01)}),
    ({"viscous_n_per_mps": 40.0}, "viscous_error", {"viscous_n_per_mps": (40.0, 0.05)}),
    ({"cogging": Cogging(0.7, 0.008, 0.3, (Harmonic(2, 0.3, 1.0),))}, "cogging",
     {"pitch_m": (0.008, 0.01), "amplitude_n": (0.7, 0.15)}),
    ({"thrust_ripple": ThrustRipple(0.03, 0.012, 0.5)}, "thrust_ripple",
     {"relative": (0.03, 0.1), "pitch_m": (0.012, 0.02)}),
    ({"thrust_lag": ThrustLag(0.0015)}, "thrust_lag", {"tau_s": (0.0015, 0.05)}),
    ({"transport_delay": TransportDelay(0.003)}, "transport_delay", {"delay_s": (0.003, 0.05)}),
]


@pytest.mark.parametrize(("blocks", "name", "expect"), CASES,
                         ids=[c[1] for c in CASES])
def test_each_effect_is_named_with_its_parameters(blocks: dict[str, Any], name: str,
                                                  expect: dict[str, tuple[float, float]]
                                                  ) -> None:
    scalars = {k: v for k, v in blocks.items() if not hasattr(v, "__dataclass_fields__")}
    effect_blocks = {k: v for k, v in blocks.items() if k not in scalars}
    from dataclasses import replace
    truth = replace(nominal_plant().with_effects(noise=NOISE, **effect_blocks), **scalars)
    result = diagnose(nominal_plant(), simulate(truth, THRUST, seed=3))
    names = [e.name for e in result.effects]
    assert names == [name], names
    found = result.effects[0]
    for key, (value, tol) in expect.items():
        assert found.params[key] == pytest.approx(value, rel=tol), (key, found.params)
        std = found.params_std.get(key)
        if std is not None and np.isfinite(std):  # the stated uncertainty covers the truth
            assert abs(found.params[key] - value) < 5 * std + 1e-3 * abs(value)
    assert found.held_out is not None and found.held_out.confirmed
    assert found.significance > 3.0 and found.explains > 0.3
    fit = result.fit
    for seg in ("estimation", "validation"):
        assert fit[seg]["nrmse_after"] < 0.85 * fit[seg]["nrmse_before"]
    # the corrected plant is a valid plant file that now holds the effect
    corrected = plant_from_dict(result.to_dict()["corrected_plant"])
    assert corrected == result.corrected


def test_group_err_equals_a_direct_projection() -> None:
    """The Gram-update ERR of a candidate family equals ||P y||²/||y||² computed directly
    by least squares on the orthogonalised columns (seed Eq. 4 for a group)."""
    truth = nominal_plant().with_effects(noise=NOISE, cogging=Cogging(0.7, 0.008))
    data = equation_data(nominal_plant(), simulate(truth, THRUST, seed=3))
    cands = Candidates.build(data)
    chosen = columns(Effect("force_offset"), data)
    q = np.linalg.qr(chosen)[0]
    i = [f.name for f in cands.families].index("cogging")
    errs = _family_err(cands, i, q, q.T @ data.y, float(data.y @ data.y))
    for k in (0, len(errs) // 2, int(np.argmax(errs))):
        g = columns(cands.families[i].members[k], data)
        g = g - q @ (q.T @ g)
        proj = g @ np.linalg.lstsq(g, data.y, rcond=None)[0]
        assert errs[k] == pytest.approx(float(proj @ proj) / float(data.y @ data.y), rel=1e-4)
    best = cands.families[i].members[int(np.argmax(errs))]
    assert best.pitch_m == pytest.approx(0.008, rel=0.03)
