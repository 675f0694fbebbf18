"""Seed §V: different NARX structures of one system share the same GFRFs.

The simulated plant (core/physics) is the motor with a stiff spring (resonance at
sqrt(k/M)/2pi = 14.7 Hz) and thrust ripple F (1 + r sin(2 pi x / p)): for small x a bilinear
x F force, so the plant's second-order kernel is, in continuous time,
H2(f1, f2) = (c/2) G(f1+f2) (G(f1) + G(f2)), c = 2 pi r / p, G = 1/(M s^2 + B s + k),
with ridges along f1, f2 and f1 + f2 = +-f0. Two different structures (lags, method, size)
are fitted to the same recording. Stated tolerances: H1 within 1e-3 relative of each other
and of the exact ZOH discretisation of G over 0-60 Hz; the same ridge set (kind, sign) with
frequencies within 5e-4 cycles/sample (0.25 Hz); |H2| on the ridges within 5 % of each other
and within 10 % of the continuous-time kernel where f1 + f2 <= 0.03.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.signal import cont2discrete

from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.frequency.ridges import h1_peaks, h2_ridges
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import Noise, Spring, ThrustRipple, nominal_plant
from pmsm_sysid.core.selection.identify import FitConfig, fit_narx
from pmsm_sysid.core.terms.model import Structure

M, B, K = 2.3213, 32.4992, 20000.0
RIPPLE, PITCH = 0.05, 0.05
FS = 500.0
STRUCTURES = {
    "ny2-nu2-iofr-8": FitConfig(structure=Structure(ny=2, nu=2, degree=2), n_terms=8,
                                method="iofr"),
    "ny4-nu4-ofr-12": FitConfig(structure=Structure(ny=4, nu=4, degree=2), n_terms=12,
                                method="ofr"),
}


def G(f: np.ndarray) -> np.ndarray:
    s = 2j * np.pi * np.asarray(f) * FS
    return 1.0 / (M * s * s + B * s + K)


@pytest.fixture(scope="module")
def fitted() -> dict[str, Any]:
    plant = nominal_plant().with_effects(
        spring=Spring(K), thrust_ripple=ThrustRipple(relative=RIPPLE, pitch_m=PITCH),
        noise=Noise(position_std=1e-7))
    u = make_excitation("multisine", 6000, FS, seed=4, f_min_hz=1.0, f_max_hz=60.0)
    rec = simulate(plant, u, seed=5)
    y, uu = rec.position[1000:], rec.thrust[1000:]
    out = {}
    for name, cfg in STRUCTURES.items():
        model = fit_narx(y, uu, cfg, FS, output_name="position").model
        out[name] = Gfrf.from_model(model), model
    names = [m.term_names for _, m in out.values()]
    assert names[0] != names[1]  # genuinely different structures
    return out


def test_h1_agrees_with_each_other_and_the_plant(fitted: dict[str, Any]) -> None:
    num, den, _ = cont2discrete(([1.0], [M, B, K]), 1 / FS, method="zoh")
    f = np.linspace(0.0, 0.12, 241)
    z = np.exp(2j * np.pi * f)
    truth = np.polyval(np.ravel(num), z) / np.polyval(den, z)
    h = [g.h(f) for g, _ in fitted.values()]
    assert np.max(np.abs(h[0] - h[1]) / np.abs(truth)) < 1e-3
    for hk in h:
        assert np.max(np.abs(hk - truth) / np.abs(truth)) < 1e-3
    f0 = np.sqrt(K / M - (B / M) ** 2 / 2) / (2 * np.pi) / FS  # |G| peak
    for g, _ in fitted.values():
        top = h1_peaks(g)[0]
        assert top.kind == "resonance" and top.freq_norm == pytest.approx(f0, abs=2e-4)


def test_same_h2_ridge_set(fitted: dict[str, Any]) -> None:
    sets = []
    for g, _ in fitted.values():
        rs = h2_ridges(g)
        sets.append({(r.kind, r.sign): r.freq_norm for r in rs})
        assert len(rs) == len(sets[-1])  # one ridge per (kind, sign)
    assert sets[0].keys() == sets[1].keys() == {
        (k, s) for k in ("f1", "f2", "f1+f2") for s in (1, -1)}
    f0 = h1_peaks(next(iter(fitted.values()))[0])[0].freq_norm
    for key in sets[0]:
        assert sets[0][key] == pytest.approx(sets[1][key], abs=5e-4)
        assert sets[0][key] == pytest.approx(f0, abs=1e-3)


def test_h2_values_agree_and_match_the_plant_kernel(fitted: dict[str, Any]) -> None:
    f1 = np.array([0.0294, 0.0294, 0.0194, 0.005, 0.01, 0.015])
    f2 = np.array([0.0, -0.02, 0.01, 0.0244, 0.01, -0.01])
    h = [np.abs(g.h(f1, f2)) for g, _ in fitted.values()]
    assert np.max(np.abs(h[0] - h[1]) / h[1]) < 0.05
    c = 2 * np.pi * RIPPLE / PITCH
    ct = np.abs(c / 2 * G(f1 + f2) * (G(f1) + G(f2)))
    for hk in h:
        assert np.max(np.abs(hk - ct) / ct) < 0.10
