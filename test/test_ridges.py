"""Peaks and ridges (core/ridges.py) on models whose ridge lines are known by construction.

A resonant AR(2) linear part 1/L(f) with a chosen nonlinearity places the ridges exactly:
u(k-1)^2 gives H2 = c z12 / L(f1+f2) (only f1+f2 = +-f0 lines), y(k-1)^2 multiplies by
H1(f1) H1(f2) (adding f1 = +-f0 and f2 = +-f0), u(k-1)^3 gives H3 = g z123 / L(f1+f2+f3)
(only the f1+f2+f3 lines of the f1 = f3 slice), y(k-1)^3 adds f1 = f3 and f2 lines. The line
positions are checked against brute-force maxima of 1/|L| and |H1| computed here.
"""

from __future__ import annotations

import numpy as np
import pytest

from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.frequency.ridges import h1_peaks, h2_ridges, h3_ridges, poles
from pmsm_sysid.core.terms.model import NarxModel

R, F0 = 0.97, 0.08
A1, A2 = 2 * R * np.cos(2 * np.pi * F0), -R * R
BASE = {"y(k-1)": A1, "y(k-2)": A2, "u(k-1)": 1.0}
FINE = np.linspace(0.0, 0.5, 500001)
Z = np.exp(-2j * np.pi * FINE)
L = 1 - A1 * Z - A2 * Z**2
F_L = float(FINE[np.argmax(1 / np.abs(L))])          # peak of 1/|L|: the f1+f2 line
F_H1 = float(FINE[np.argmax(np.abs(Z / L))])          # peak of |H1|: the f1 line
TOL = 5e-4                                            # 2 refinement steps


def gfrf(extra: dict[str, float]) -> Gfrf:
    return Gfrf.from_model(NarxModel.from_terms({**BASE, **extra}, sample_rate_hz=500.0))


def kinds(ridges: list) -> set[tuple[str, int]]:
    return {(r.kind, r.sign) for r in ridges}


def near(ridges: list, f: float) -> list:
    return [r for r in ridges if abs(r.freq_norm - f) < TOL]


def test_h1_resonance_peak_and_pole() -> None:
    g = gfrf({"u(k-1)^2": 0.3})
    peaks = h1_peaks(g)
    assert [p.kind for p in peaks] == ["resonance"]
    p = peaks[0]
    assert p.freq_norm == pytest.approx(F_H1, abs=2e-6)
    h = np.exp(-2j * np.pi * p.freq_norm) / (1 - A1 * np.exp(-2j * np.pi * p.freq_norm)
                                             - A2 * np.exp(-4j * np.pi * p.freq_norm))
    assert p.gain_db == pytest.approx(20 * np.log10(abs(h)), abs=1e-9)
    assert p.phase_deg == pytest.approx(np.degrees(np.angle(h)), abs=1e-7)
    assert p.freq_hz == pytest.approx(500.0 * p.freq_norm)
    assert p.pole_radius == pytest.approx(R, abs=1e-12)
    pl = poles(g)
    assert [x.radius for x in pl] == pytest.approx([R, R])
    assert pl[0].freq_norm == pytest.approx(F0, abs=1e-12)


def test_mass_damper_has_no_resonance() -> None:
    """Nominal plant, ZOH at 500 Hz: speed/thrust = b z^-1/(1 - a z^-1), low-pass only."""
    a = np.exp(-32.4992 / 2.3213 / 500.0)
    b = (1 - a) / 32.4992
    g = Gfrf.from_model(NarxModel.from_terms({"y(k-1)": a, "u(k-1)": b}, sample_rate_hz=500.0))
    peaks = h1_peaks(g)
    assert [p.kind for p in peaks] == ["dc"]
    assert peaks[0].gain_db == pytest.approx(20 * np.log10(1 / 32.4992), abs=1e-9)
    assert h2_ridges(g) == [] and h3_ridges(g) == []


def test_h2_input_square_gives_only_sum_lines() -> None:
    r2 = h2_ridges(gfrf({"u(k-1)^2": 0.3}))
    assert kinds(r2) == {("f1+f2", 1), ("f1+f2", -1)}
    assert all(abs(r.freq_norm - F_L) < TOL for r in r2)


def test_h2_output_square_adds_release_lines() -> None:
    r2 = h2_ridges(gfrf({"y(k-1)^2": 0.3}))
    assert kinds(r2) == {(k, s) for k in ("f1", "f2", "f1+f2") for s in (1, -1)}
    for r in r2:
        assert r.freq_norm == pytest.approx(F_L if r.kind == "f1+f2" else F_H1, abs=TOL)
        assert r.freq_hz == pytest.approx(500.0 * r.freq_norm)
        assert r.prominence_db > 20.0 and r.dominant


def test_h3_input_cube_gives_only_total_sum_lines() -> None:
    g = gfrf({"u(k-1)^3": 0.3})
    assert h2_ridges(g) == []
    r3 = h3_ridges(g)
    assert kinds(r3) == {("f1+f2+f3", 1), ("f1+f2+f3", -1)}
    assert all(abs(r.freq_norm - F_L) < TOL for r in r3)


def test_h3_output_cube_lines() -> None:
    g = gfrf({"y(k-1)^3": 0.3})
    r3 = h3_ridges(g)
    at_f0 = [r for r in r3 if abs(r.freq_norm - F0) < 2e-3]
    assert kinds(at_f0) == {(k, s) for k in ("f1", "f2", "f1+f2+f3") for s in (1, -1)}
    # H1(f1)^2 on the f1 = f3 line: the strongest, ~2 x 30 dB above the others
    assert r3[0].kind == "f1" and r3[0].level_db - max(
        r.level_db for r in at_f0 if r.kind != "f1") > 25.0


def test_h3_pair_denominator_is_named_f1_plus_f3() -> None:
    """u^2 and y u terms put H2(f1, f3) inside H3, hence 1/L(f1 + f3) = 1/L(2 f1) on the
    slice: a vertical line at f0/2, which is reported as f1 + f3 = f0."""
    g = gfrf({"u(k-1)^2": 0.3, "y(k-1)u(k-1)": 0.2})
    pk = tuple(p.freq_norm for p in h1_peaks(g))
    r3 = h3_ridges(g, h1_peak_norm=pk)
    f13 = [r for r in r3 if r.kind == "f1+f3"]
    assert {r.sign for r in f13} == {1, -1}
    assert all(abs(r.freq_norm - F_L) < 2 * TOL for r in f13)
    assert near(r3, F_L)  # also f1+f2(+f3) lines at f0
    without = h3_ridges(g)  # no H1 peaks given: the same line is called f1 at f0/2
    assert any(r.kind == "f1" and abs(r.freq_norm - F_L / 2) < TOL for r in without)


def test_linear_model_has_no_ridges() -> None:
    g = gfrf({})
    assert h2_ridges(g) == [] and h3_ridges(g) == []
    assert len(h1_peaks(g)) == 1
