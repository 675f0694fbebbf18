"""Plant files: the paper's Table 1, validation with one clear error line, round trips."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from pmsm_sysid.core.errors import PlantError
from pmsm_sysid.core.physics.plant import (
    EFFECT_BLOCKS,
    Cogging,
    CoulombFriction,
    Harmonic,
    Noise,
    Plant,
    Spring,
    ThrustLag,
    ThrustRipple,
    dump_plant,
    electrical_lag,
    load_plant,
    nominal_plant,
    packaged_plant_path,
    plant_from_dict,
    plant_to_dict,
)

REPO = Path(__file__).resolve().parents[1]
PLANTS = sorted((REPO / "plants").glob("*.yaml"))


def test_nominal_is_table_1() -> None:
    p = nominal_plant()
    assert p.mass_kg == 2.3213
    assert p.viscous_n_per_mps == 32.4992
    assert p.rs_ohm == pytest.approx(11.6504 / 3.0, abs=5e-5)
    assert p.ls_h == pytest.approx(0.0048 / 3.0, rel=1e-12)
    assert p.flux_wb == 0.4849
    assert p.sample_rate_hz == 500.0
    assert p.effects == ()
    # winding time constant L/R of the issue text: about 0.41 ms
    assert p.electrical_tau_s == pytest.approx(0.0016 / 3.8835)
    assert electrical_lag(p) == ThrustLag(tau_s=p.electrical_tau_s)


def test_packaged_and_example_nominal_files_equal_table_1() -> None:
    assert load_plant(packaged_plant_path("nominal")) == nominal_plant()
    assert load_plant(REPO / "plants" / "nominal.yaml") == nominal_plant()
    assert load_plant("nominal") == nominal_plant()  # bare name = packaged file


def test_example_plants_cover_every_effect() -> None:
    names = {p.name for p in PLANTS}
    assert {"nominal.yaml", "cogging.yaml", "coulomb.yaml", "all_effects.yaml"} <= names
    everything = load_plant(REPO / "plants" / "all_effects.yaml")
    assert set(everything.effects) == set(EFFECT_BLOCKS)
    assert everything.thrust_lag is not None
    assert everything.thrust_lag.tau_s == pytest.approx(everything.ls_h / everything.rs_ohm)


@pytest.mark.parametrize("path", PLANTS, ids=[p.name for p in PLANTS])
def test_example_plants_round_trip(path: Path) -> None:
    plant = load_plant(path)
    assert plant_from_dict(plant_to_dict(plant)) == plant
    assert plant_from_dict(yaml.safe_load(dump_plant(plant))) == plant


def test_to_dict_omits_disabled_effects_and_keeps_keys() -> None:
    p = nominal_plant().with_effects(coulomb_friction=CoulombFriction(2.0))
    d = plant_to_dict(p)
    assert d["coulomb_friction"] == {"amplitude_n": 2.0, "smoothing_mps": 1e-3}
    assert "cogging" not in d and "noise" not in d


def test_disabled_blocks_by_null_or_enabled_false() -> None:
    d = {"cogging": None, "spring": {"enabled": False, "stiffness_n_per_m": 5.0},
         "coulomb_friction": {"enabled": True, "amplitude_n": 1.5}}
    p = plant_from_dict(d)
    assert p.cogging is None and p.spring is None
    assert p.coulomb_friction == CoulombFriction(1.5)


def test_electrical_tau_and_exponents_without_a_dot(tmp_path: Path) -> None:
    path = tmp_path / "plant.yaml"  # PyYAML alone reads 4e-3 (no dot) as the string '4e-3'
    path.write_text("rs_ohm: 2.0\nls_h: 4e-3\nthrust_lag: {tau_s: electrical}\n")
    p = load_plant(path)
    assert p.ls_h == 4e-3
    assert p.thrust_lag == ThrustLag(tau_s=2e-3)
    path.write_text("ls_h: '4e-3'\n")  # a quoted string is a string, never a number
    with pytest.raises(PlantError, match="ls_h must be a number, got '4e-3'"):
        load_plant(path)


def test_harmonics_parse() -> None:
    p = plant_from_dict({"cogging": {"amplitude_n": 3, "pitch_m": 0.01, "harmonics": [
        {"order": 2, "amplitude_n": 1.0}, {"order": 3, "amplitude_n": 0.5, "phase_rad": 1}]}})
    assert p.cogging == Cogging(3.0, 0.01, 0.0, (Harmonic(2, 1.0), Harmonic(3, 0.5, 1.0)))


@pytest.mark.parametrize(("data", "fragment"), [
    ({"mas_kg": 2.0}, "unknown key 'mas_kg' (did you mean 'mass_kg'?)"),
    ({"cogging": {"amplitude_n": 1, "pich_m": 0.1}}, "did you mean 'pitch_m'"),
    ({"coulomb": {"amplitude_n": 1}}, "did you mean 'coulomb_friction'"),
    ({"mass_kg": -1.0}, "mass_kg must be > 0"),
    ({"mass_kg": 0}, "mass_kg must be > 0"),
    ({"mass_kg": float("nan")}, "mass_kg must be finite"),
    ({"viscous_n_per_mps": float("inf")}, "must be finite"),
    ({"mass_kg": "heavy"}, "mass_kg must be a number, got 'heavy'"),
    ({"mass_kg": True}, "mass_kg must be a number"),
    ({"mass_kg": [1, 2]}, "mass_kg must be a number"),
    ({"substeps": 2.5}, "substeps must be an integer"),
    ({"cogging": {"amplitude_n": 1}}, "cogging is missing pitch_m"),
    ({"cogging": 3}, "cogging must be a mapping"),
    ({"cogging": {"amplitude_n": 1, "pitch_m": 0.0}}, "cogging.pitch_m must be > 0"),
    ({"cogging": {"amplitude_n": 1, "pitch_m": 1, "harmonics": {"order": 2}}},
     "harmonics must be a list"),
    ({"cogging": {"amplitude_n": 1, "pitch_m": 1, "harmonics": [{"order": 1.5,
                                                                  "amplitude_n": 1}]}},
     "harmonics[0].order must be an integer"),
    ({"thrust_ripple": {"relative": 1.5, "pitch_m": 0.03}}, "between -1 and 1"),
    ({"thrust_lag": {"tau_s": -1e-3}}, "thrust_lag.tau_s must be >= 0"),
    ({"noise": {"speed_std": -1}}, "noise.speed_std must be >= 0"),
    ({"spring": {"enabled": "yes", "stiffness_n_per_m": 1}}, "enabled must be true or false"),
])
def test_bad_dicts_give_one_clear_line(data: dict[str, object], fragment: str) -> None:
    with pytest.raises(PlantError) as info:
        plant_from_dict(data)
    msg = str(info.value)
    assert fragment in msg
    assert "\n" not in msg


@pytest.mark.parametrize(("text", "fragment"), [
    ("mass_kg: [1, 2\n", "not valid YAML at line"),
    ("- 1\n- 2\n", "must be a YAML mapping"),
    ("mass_kg: .nan\n", "mass_kg must be finite"),
    ("mass_kg: -2.0\n", "mass_kg must be > 0"),
    ("massa: 1\n", "unknown key 'massa'"),
])
def test_bad_files(tmp_path: Path, text: str, fragment: str) -> None:
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    with pytest.raises(PlantError) as info:
        load_plant(path)
    assert fragment in str(info.value)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(PlantError, match="no such plant file"):
        load_plant(tmp_path / "nope.yaml")
    with pytest.raises(PlantError, match="cannot read plant file"):
        load_plant(tmp_path)


def test_empty_file_is_nominal(tmp_path: Path) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text("# nothing\n")
    assert load_plant(path) == nominal_plant()


def test_direct_construction_is_validated() -> None:
    with pytest.raises(PlantError, match="mass_kg must be > 0"):
        Plant(mass_kg=0.0)
    with pytest.raises(PlantError, match=r"spring\.stiffness_n_per_m must be >= 0"):
        Plant(spring=Spring(-1.0))
    with pytest.raises(PlantError, match="must be a Noise block"):
        Plant(noise=Spring(1.0))  # type: ignore[arg-type]
    with pytest.raises(PlantError, match="between -1 and 1"):
        Plant(thrust_ripple=ThrustRipple(relative=-1.0, pitch_m=0.1))


finite = st.floats(min_value=-50, max_value=50, allow_nan=False)
positive = st.floats(min_value=1e-4, max_value=10, allow_nan=False)


@st.composite
def plants(draw: st.DrawFn) -> Plant:
    harmonics = tuple(Harmonic(draw(st.integers(2, 6)), draw(finite), draw(finite))
                      for _ in range(draw(st.integers(0, 2))))
    return Plant(
        mass_kg=draw(positive), viscous_n_per_mps=draw(st.floats(0, 100)),
        substeps=draw(st.integers(1, 20)),
        cogging=draw(st.none() | st.just(Cogging(draw(finite), draw(positive), draw(finite),
                                                 harmonics))),
        coulomb_friction=draw(st.none() | st.builds(CoulombFriction, finite, positive)),
        thrust_lag=draw(st.none() | st.builds(ThrustLag, st.floats(0, 0.01))),
        noise=draw(st.none() | st.builds(Noise, st.floats(0, 1), st.floats(0, 1),
                                         st.floats(0, 1))),
    )


@settings(max_examples=60, deadline=None)
@given(plants())
def test_round_trip_property(plant: Plant) -> None:
    assert plant_from_dict(plant_to_dict(plant)) == plant
    assert plant_from_dict(yaml.safe_load(dump_plant(plant))) == plant
    assert all(math.isfinite(v) for v in (plant.mass_kg, plant.viscous_n_per_mps))
