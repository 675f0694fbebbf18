"""Locate over frequency: GFRF ridges and peaks of the real data's NARX that its noisy
simulated twin's lacks (pmsm_sysid.core.discrepancy.gfrf_compare).

Independent truths: a static quadratic thrust distortion F = u + c u² through the
mass-damper has H2(f1, f2) = c G(f1 + f2), a ridge on f1 + f2 = 0 at |G(0)| c = c/B; a spring
k on the mass-damper resonates at sqrt(k/M - (B/2M)²)/2π with |H1| = 1/B there.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pmsm_sysid.bagio import read_recording
from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.discrepancy.gfrf_compare import gfrf_where, only_in_first
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import CoulombFriction, Noise, Spring, nominal_plant
from pmsm_sysid.core.recording.signals import Recording

REPO = Path(__file__).resolve().parents[1]
NOISE = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0)
NOMINAL = nominal_plant()
FS = 500.0


def _drive(seed: int) -> np.ndarray:
    return make_excitation("multisine", 2500, FS, seed=seed, amplitude_n=30.0)


def _quadratic(seed: int, c: float) -> Recording:
    """The motor driven by u + c u², the recording holding the commanded u."""
    u = _drive(seed)
    rec = simulate(NOMINAL.with_effects(noise=NOISE), u + c * u ** 2, seed=seed + 10)
    return replace(rec, thrust=u)


@pytest.mark.parametrize("seed", [1, 3])
def test_a_quadratic_thrust_distortion_is_a_ridge_only_in_real(seed: int) -> None:
    c = 0.01
    d = gfrf_where(NOMINAL, _quadratic(seed, c))
    assert d["axis"] == "frequency" and d["source"] == "gfrf"
    assert d["real"]["significant"] and not d["twin"]["significant"]
    assert d["real"]["weak"]  # "weak" by output variance, yet far above the noise
    (ridge,) = [r for r in d["ridges_only_in_real"] if r["kind"] == "f1+f2"]
    assert ridge["freq_hz"] <= d["tolerance_hz"]
    assert ridge["gain_db"] == pytest.approx(20 * math.log10(c / NOMINAL.viscous_n_per_mps),
                                             abs=4.0)
    assert d["peaks_only_in_real"] == []
    assert "H2 ridges only in the real data's model: f1+f2 at 0.0 Hz" in d["note"]
    # the twin's noise is matched to the real model's one-step residual
    assert d["twin"]["residual_std"] == pytest.approx(d["real"]["residual_std"], rel=0.1)
    assert math.isfinite(d["timing_ms"]) and d["timing_ms"] > 0  # (its speed: bench/)


def test_a_spring_resonance_is_a_peak_only_in_real() -> None:
    m, b = NOMINAL.mass_kg, NOMINAL.viscous_n_per_mps
    k = m * (2 * math.pi * 20.0) ** 2
    rec = simulate(NOMINAL.with_effects(noise=NOISE, spring=Spring(k)), _drive(2), seed=12)
    d = gfrf_where(NOMINAL, rec)
    fn = math.sqrt(k / m - (b / (2 * m)) ** 2) / (2 * math.pi)
    (peak,) = d["peaks_only_in_real"]
    assert peak["kind"] == "resonance"
    assert peak["freq_hz"] == pytest.approx(fn, abs=0.2)
    assert peak["gain_db"] == pytest.approx(-20 * math.log10(b), abs=1.0)
    assert d["ridges_only_in_real"] == []
    # the plant that has the spring: its twin resonates there too
    with_spring = gfrf_where(NOMINAL.with_effects(spring=Spring(k)), rec)
    assert with_spring["peaks_only_in_real"] == []


def test_strong_coulomb_friction_is_a_nonlinearity_the_twin_lacks() -> None:
    """20 N of Coulomb friction: an odd nonlinearity, which a degree-2 NARX takes as
    significant bilinear terms without a distinct ridge line; the twin of the plant that
    has the friction is nonlinear too."""
    plant = NOMINAL.with_effects(noise=NOISE, coulomb_friction=CoulombFriction(20.0))
    rec = simulate(plant, _drive(1), seed=11)
    d = gfrf_where(NOMINAL, rec)
    assert d["real"]["significant"] and not d["twin"]["significant"]
    assert d["ridges_only_in_real"] == []
    assert "significant nonlinear terms the twin's lacks" in d["note"]
    same = gfrf_where(replace(plant, noise=None), rec)
    assert same["real"]["significant"] and same["twin"]["significant"]
    assert same["ridges_only_in_real"] == []


@pytest.mark.parametrize("seed", [4, 5])
def test_no_ridges_on_the_nominal_motor(seed: int) -> None:
    d = gfrf_where(NOMINAL, simulate(NOMINAL.with_effects(noise=NOISE), _drive(seed),
                                     seed=seed + 10))
    assert not d["real"]["significant"] and not d["twin"]["significant"]
    assert d["ridges_only_in_real"] == [] and d["peaks_only_in_real"] == []
    assert d["note"].startswith("neither")


def test_matching_rules() -> None:
    """Same family within the tolerance matches; f1 and f2 are one family (H2 is
    symmetric), f1+f2 another; duplicates within a tolerance are listed once."""
    real = [{"kind": "f1", "freq_hz": 10.0}, {"kind": "f1+f2", "freq_hz": 10.0},
            {"kind": "f2", "freq_hz": -30.0}, {"kind": "f1", "freq_hz": 30.4}]
    twin = [{"kind": "f2", "freq_hz": 11.9}, {"kind": "f1+f2", "freq_hz": 40.0}]
    out = only_in_first(real, twin, 2.0, ridge=True)
    assert [(r["kind"], r["freq_hz"]) for r in out] == [("f1+f2", 10.0), ("f2", 30.0)]
    assert only_in_first(real, twin, 1.0, ridge=True)[0] == {
        "kind": "f1", "freq_hz": 10.0, "gain_db": None, "order": 2, "prominence_db": None,
        "dominant": None}
    peaks = [{"kind": "resonance", "freq_hz": 20.0}, {"kind": "dc", "freq_hz": 0.0}]
    assert only_in_first(peaks, [{"kind": "resonance", "freq_hz": 0.5}], 1.0,
                         ridge=False) == [{"kind": "resonance", "freq_hz": 20.0,
                                           "gain_db": None}]


def test_unusable_data_is_said_not_raised() -> None:
    n = 40
    rec = Recording(t=np.arange(n) / FS, thrust=np.ones(n), speed=np.zeros(n),
                    position=np.zeros(n), sample_rate_hz=FS)
    d = gfrf_where(NOMINAL, rec)
    assert d["skipped"] and d["ridges_only_in_real"] == []
    assert d["note"].startswith("GFRF comparison not possible")


def test_diagnose_reports_the_comparison_in_where() -> None:
    """In the diagnose JSON: a mismatch.where entry with source gfrf; on the nominal bag it
    says that there is nothing to compare, and --no-gfrf leaves it out."""
    rec = read_recording(REPO / "bags" / "paper_speed_nominal").recording
    res = diagnose(NOMINAL, rec, options=DiagnoseOptions(replay=False))
    where = json.loads(json.dumps(res.to_dict()))["mismatch"]["where"]
    (g,) = [w for w in where if w.get("source") == "gfrf"]
    assert g["axis"] == "frequency"
    assert g["ridges_only_in_real"] == [] and g["peaks_only_in_real"] == []
    assert g["window"][1] <= int(0.7 * len(rec))  # estimation data only
    assert "GFRF (NARX ny=10 nu=10 degree 2" in res.summary()
    off = diagnose(NOMINAL, rec, options=DiagnoseOptions(replay=False, gfrf=False))
    assert all(w.get("source") != "gfrf" for w in off.to_dict()["mismatch"]["where"])
