"""The comparison of two fitted plants in isolation: the combined error, the corrected
plant and the words side by side (no fitting here: rows and plants are given)."""

from __future__ import annotations

import math

import pytest

from pmsm_sysid.core.discrepancy.changes import Change, _scalar, _significance
from pmsm_sysid.core.discrepancy.sidebyside import apply_changes, in_words
from pmsm_sysid.core.physics.plant import Cogging, CoulombFriction, Plant

SIM = Plant(mass_kg=3.1, viscous_n_per_mps=25.0, sample_rate_hz=1000.0,
            cogging=Cogging(0.8, 0.006, 0.3), coulomb_friction=CoulombFriction(1.0))
REAL = Plant(mass_kg=3.224, viscous_n_per_mps=25.0, sample_rate_hz=500.0,
             coulomb_friction=CoulombFriction(2.1))


def test_a_difference_counts_against_both_errors() -> None:
    """3.3 ± 0.01 kg against 3.1 ± 0.1 kg: z = 0.2 / 0.1005, not 20."""
    t = _scalar("mass_error", "mass_kg", (3.1, 0.1), (3.3, 0.01), None)
    assert t.std == pytest.approx(math.hypot(0.1, 0.01))
    assert t.z == pytest.approx(0.2 / math.hypot(0.1, 0.01))
    assert _significance(t.log10_p, 5) < 3.0  # no row at alpha 1e-3 over 5 tests
    alone = _scalar("mass_error", "mass_kg", (3.1, 0.0), (3.3, 0.01), None)
    assert _significance(alone.log10_p, 5) > 50
    absent = _scalar("coulomb_friction", "amplitude_n", None, (2.0, 0.05), (0.1, 0.5))
    assert absent.sim is None and absent.absent == (0.1, 0.5)
    assert absent.z == pytest.approx(1.9 / math.hypot(0.05, 0.5))


def _row(effect: str, param: str, sim: float | None, real: float | None) -> Change:
    return Change(effect, param, sim, real, 0.01, 10.0, 20.0, "high")


def test_the_simulators_plant_with_the_changes_applied() -> None:
    rows = [_row("mass_error", "mass_kg", 3.1, 3.224),
            _row("coulomb_friction", "amplitude_n", 1.0, 2.1),
            _row("cogging", "amplitude_n", 0.8, None)]
    p = apply_changes(SIM, REAL, rows)
    assert p.mass_kg == 3.224 and p.viscous_n_per_mps == 25.0
    assert p.coulomb_friction == CoulombFriction(2.1)
    assert p.cogging is None
    assert p.sample_rate_hz == 1000.0  # still the simulator's plant
    bare = apply_changes(SIM.with_effects(coulomb_friction=None), REAL,
                         [_row("coulomb_friction", "amplitude_n", None, 2.1)])
    assert bare.coulomb_friction == REAL.coulomb_friction


def test_words_side_by_side() -> None:
    assert in_words(_row("mass_error", "mass_kg", 3.1, 3.224), SIM, REAL).startswith(
        "the real axis is 4% heavier (3.224 ± 0.01 kg against 3.1 kg)")
    sim_no_friction = SIM.with_effects(coulomb_friction=None)
    assert in_words(_row("coulomb_friction", "amplitude_n", None, 2.1), sim_no_friction,
                    REAL) == "the real axis has Coulomb friction of 2.1 N the simulation lacks"
    assert in_words(_row("cogging", "amplitude_n", 0.8, None), SIM, REAL) == (
        "the simulation has a cogging (0.8 N at a 6 mm pitch) the real axis does not show")
    assert in_words(_row("coulomb_friction", "amplitude_n", 1.0, 2.1), SIM, REAL).startswith(
        "the real axis's Coulomb friction amplitude is stronger: 2.1 N")
    assert "less viscous damping" in in_words(
        _row("viscous_error", "viscous_n_per_mps", 25.0, 20.0), SIM, REAL)
