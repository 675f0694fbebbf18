"""Fitted coefficients to the effect parameters diagnose reports (± standard errors) and plant
blocks.

Sign conventions follow :mod:`pmsm_sysid.core.physics.motor` (``F = M a + B v + F_effects``):
cogging ``A sin(2π x/p + φ)`` has regressor coefficients (A cos φ, A sin φ); thrust ripple
``-r sin(2π x/p + φ) F`` has (-r cos φ, -r sin φ). Amplitude and phase errors come from the
coefficient covariance by the delta method; a pitch's from the wavenumber's (σ_p = p² σ_k).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..physics.plant import (
    Cogging,
    CoulombFriction,
    ForceOffset,
    Harmonic,
    Plant,
    Spring,
    StribeckFriction,
    ThrustLag,
    ThrustRipple,
    TransportDelay,
)
from .estimate import Fit
from .library import Effect

FloatArray = NDArray[np.float64]


def _polar(b: FloatArray, cov: FloatArray) -> tuple[float, float, float, float]:
    """(amplitude, phase, σ_amplitude, σ_phase) of s sin + c cos = A sin(θ + φ)."""
    s, c = float(b[0]), float(b[1])
    amp = math.hypot(s, c)
    phase = math.atan2(c, s)
    if amp == 0:
        return 0.0, 0.0, float("nan"), float("nan")
    ga = np.array([s, c]) / amp
    gp = np.array([-c, s]) / amp**2
    return amp, phase, _sd(float(ga @ cov @ ga)), _sd(float(gp @ cov @ gp))


def _sd(var: float) -> float:
    return math.sqrt(var) if var >= 0 else float("nan")


def effect_params(fit: Fit, k: int, plant: Plant) -> tuple[dict[str, Any], dict[str, float]]:
    """The reported params of effect k of ``fit`` and their standard errors."""
    e = fit.effects[k]
    b = fit.beta[fit.slices()[k]]
    cov = fit.beta_cov(k)
    se = fit.eta_std(k)
    if e.name in ("force_offset", "coulomb_friction", "spring", "mass_error",
                  "viscous_error"):
        key, base = {
            "force_offset": ("amplitude_n", 0.0), "coulomb_friction": ("amplitude_n", 0.0),
            "spring": ("stiffness_n_per_m", 0.0), "mass_error": ("mass_kg", plant.mass_kg),
            "viscous_error": ("viscous_n_per_mps", plant.viscous_n_per_mps)}[e.name]
        params: dict[str, Any] = {key: base + float(b[0])}
        if e.name in ("mass_error", "viscous_error"):
            params["change" + key[key.index("_"):]] = float(b[0])
        return params, {key: _sd(float(cov[0, 0]))}
    if e.name == "stribeck_friction":
        return ({"static_n": float(b[0]), "velocity_mps": e.velocity_mps},
                {"static_n": _sd(float(cov[0, 0])), "velocity_mps": e.velocity_mps * se})
    if e.name == "thrust_lag":
        return {"tau_s": e.tau_s}, {"tau_s": se}
    if e.name == "transport_delay":
        return {"delay_s": e.delay_s}, {"delay_s": se}
    if e.name == "thrust_ripple":
        amp, ph, sa, sp = _polar(-b, cov)
        return ({"relative": amp, "pitch_m": e.pitch_m, "phase_rad": ph},
                {"relative": sa, "pitch_m": e.pitch_m**2 * se, "phase_rad": sp})
    return _cogging_params(e, b, fit.beta_cov(k), se)


def _cogging_params(e: Effect, b: FloatArray, cov: FloatArray,
                    se_k: float) -> tuple[dict[str, Any], dict[str, float]]:
    terms = []
    for j, h in enumerate(e.orders):
        sl = slice(2 * j, 2 * j + 2)
        terms.append((h, *_polar(b[sl], cov[sl, sl])))
    fund = next((t for t in terms if t[0] == 1), (1, 0.0, 0.0, float("nan"), float("nan")))
    params: dict[str, Any] = {
        "amplitude_n": fund[1], "pitch_m": e.pitch_m, "phase_rad": fund[2],
        "harmonics": [{"order": h, "amplitude_n": a, "phase_rad": p}
                      for h, a, p, _, _ in terms if h != 1]}
    std = {"amplitude_n": fund[3], "pitch_m": e.pitch_m**2 * se_k, "phase_rad": fund[4]}
    for h, _, _, sa, _ in terms:
        if h != 1:
            std[f"harmonic_{h}_amplitude_n"] = sa
    return params, std


def corrected_plant(plant: Plant,
                    named: list[tuple[str, dict[str, Any]]]) -> tuple[Plant, list[str]]:
    """The nominal plant with each found effect added (additive blocks are summed)."""
    p = plant
    notes: list[str] = []
    for name, params in named:
        p, note = _apply(p, name, params)
        if note:
            notes.append(note)
    return p, notes


def _apply(p: Plant, name: str, q: dict[str, Any]) -> tuple[Plant, str]:
    note = ""
    if name == "mass_error":
        return replace(p, mass_kg=q["mass_kg"]), note
    if name == "viscous_error":
        return replace(p, viscous_n_per_mps=max(q["viscous_n_per_mps"], 0.0)), note
    if name == "force_offset":
        old = p.force_offset.amplitude_n if p.force_offset else 0.0
        return replace(p, force_offset=ForceOffset(old + q["amplitude_n"])), note
    if name == "coulomb_friction":
        cf = p.coulomb_friction
        amp = q["amplitude_n"] + (cf.amplitude_n if cf else 0.0)
        return replace(p, coulomb_friction=CoulombFriction(amp)), note
    if name == "stribeck_friction":
        return replace(p, stribeck_friction=StribeckFriction(
            max(q["static_n"], 0.0), q["velocity_mps"])), note
    if name == "spring":
        old = p.spring.stiffness_n_per_m if p.spring else 0.0
        return replace(p, spring=Spring(max(old + q["stiffness_n_per_m"], 0.0))), note
    if name == "thrust_lag":
        return replace(p, thrust_lag=ThrustLag(q["tau_s"])), note
    if name == "transport_delay":
        return replace(p, transport_delay=TransportDelay(q["delay_s"])), note
    if name == "thrust_ripple":
        if p.thrust_ripple is not None:
            note = "thrust_ripple: the nominal ripple block was replaced by the one found"
        return replace(p, thrust_ripple=ThrustRipple(
            min(q["relative"], 0.99), q["pitch_m"], q["phase_rad"])), note
    if name == "cogging":
        if p.cogging is not None:
            note = "cogging: the nominal cogging block was replaced by the one found"
        harm = tuple(Harmonic(int(h["order"]), h["amplitude_n"], h["phase_rad"])
                     for h in q["harmonics"])
        return replace(p, cogging=Cogging(q["amplitude_n"], q["pitch_m"], q["phase_rad"],
                                          harm)), note
    return p, note
