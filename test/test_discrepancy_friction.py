"""Friction through a noisy speed: the regressors are E[f(v) | smoothed speed] under the
speed's own distribution, which dwells near zero at every reversal of a positioning move.

The flat-prior calibration (the sign widened by the noise) took about 30 % off the static
Stribeck force at 1.7 mm/s of speed noise under a position loop; the deconvolved prior
keeps it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.special import erf

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from battery_plant import Case, Truth, record

from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.plantfit.calibration import SpeedPrior, friction_values

FAST = DiagnoseOptions(replay=False, gfrf=False)
BASE = 1e-3


def test_expected_sign_under_a_dwelling_speed_matches_monte_carlo() -> None:
    """Half the time near standstill (within 1 mm/s), half moving, 2 mm/s of noise: given
    v̂ = 2 mm/s the true speed is probably near zero, so E[sign(v) | v̂] is well below the
    flat-prior erf. (A dwell ten times narrower than the noise is deconvolved only in part:
    50 Richardson-Lucy iterations are the regularisation.)"""
    rng = np.random.default_rng(0)
    n, sigma = 400_000, 0.002
    v = np.where(rng.random(n) < 0.5, rng.normal(0.0, 1e-3, n), rng.uniform(-0.1, 0.1, n))
    vhat = v + rng.normal(0.0, sigma, n)
    prior = SpeedPrior.from_speeds(vhat, sigma, BASE)
    fc = prior.expected(friction_values(prior.grid, BASE))
    for at in (0.001, 0.002, 0.004, 0.006, 0.01):
        near = np.abs(vhat - at) < 2e-4
        mc = float(np.mean(np.tanh(v[near] / BASE)))
        assert np.interp(at, prior.grid, fc) == pytest.approx(mc, abs=0.04)
    flat = float(erf(0.002 / (np.sqrt(2.0) * np.hypot(sigma, BASE / 1.2533))))
    mc2 = float(np.mean(np.tanh(v[np.abs(vhat - 0.002) < 2e-4] / BASE)))
    assert flat - mc2 > 0.3  # the flat prior is the wrong calibration here


def test_a_prior_is_deconvolved_once_per_speed_record_and_shared_read_only() -> None:
    """A fit builds the equation data of one recording for each plant it tries: the prior of
    the same speeds (same bytes, noise and base) is the same object, computed once; other
    speeds, another noise or another base give their own; nobody can change a shared one."""
    rng = np.random.default_rng(2)
    v = rng.uniform(-0.1, 0.1, 4000)
    first = SpeedPrior.from_speeds(v, 0.002, BASE)
    assert SpeedPrior.from_speeds(v.copy(), 0.002, BASE) is first
    fresh = SpeedPrior._deconvolved(v, 0.002, BASE)  # what the cache holds, computed anew
    for name in ("grid", "density", "kernel"):
        assert np.array_equal(getattr(first, name), getattr(fresh, name))
    w = v.copy()
    w[17] += 1e-9
    assert SpeedPrior.from_speeds(w, 0.002, BASE) is not first
    assert SpeedPrior.from_speeds(v, 0.003, BASE) is not first
    assert SpeedPrior.from_speeds(v, 0.002, 2 * BASE) is not first
    with pytest.raises(ValueError):
        first.density[0] = 1.0


def test_without_noise_the_calibration_is_the_function_itself() -> None:
    rng = np.random.default_rng(1)
    v = rng.uniform(-0.2, 0.2, 5000)
    prior = SpeedPrior.from_speeds(v, 0.0, BASE)
    grid = prior.grid
    assert np.allclose(prior.expected(friction_values(grid, BASE, 0.01)),
                       friction_values(grid, BASE, 0.01), atol=1e-9)


@pytest.mark.parametrize("seed", [1, 2])
def test_stribeck_under_speed_noise_in_a_position_loop(seed: int) -> None:
    """1.5 N Coulomb + 2 N Stribeck at 10 mm/s, 5 mm/s speed and 10 µm position noise:
    the static force within 25 % (it came out 28-30 % low with the flat prior)."""
    case = Case("stribeck", Truth(coulomb=1.5, stribeck=2.0, stribeck_v=0.01), "closed",
                "multisine", "high", seed)
    result = diagnose(nominal_plant(), record(case, seed), record(case, seed + 100), FAST)
    named = {e.name: e for e in result.effects}
    assert named["coulomb_friction"].params["amplitude_n"] == pytest.approx(1.5, rel=0.1)
    assert named["stribeck_friction"].params["static_n"] == pytest.approx(2.0, rel=0.25)


@pytest.mark.parametrize("seed", [1, 2])
def test_coulomb_alone_under_the_same_noise_grows_no_hump(seed: int) -> None:
    case = Case("coulomb", Truth(coulomb=2.5), "closed", "multisine", "high", seed)
    result = diagnose(nominal_plant(), record(case, seed), record(case, seed + 100), FAST)
    assert [e.name for e in result.effects] == ["coulomb_friction"]
    assert result.effects[0].params["amplitude_n"] == pytest.approx(2.5, rel=0.05)
