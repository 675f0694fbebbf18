"""Interval means: what the velocity increment of one sample interval integrates.

Under zero-order hold the thrust is constant over [t_k, t_k+1) but the force
the mover feels is not: a lag or delay reshapes the command, and the position- and
speed-dependent effects change as the mover travels. The equation error compares interval
means, so every regressor here is the mean of its force over the interval, computed in
closed form with the state taken linear in time within the interval.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter
from scipy.special import erf

from ..physics.plant import SIGN_SMOOTHING_MPS, Plant
from .calibration import SpeedPrior, calibrated_friction

FloatArray = NDArray[np.float64]


def interval_force(cmd: FloatArray, period: float, tau: float = 0.0,
                   delay: float = 0.0) -> FloatArray:
    """Mean force over each sample interval for a ZOH command through a delay and a lag.

    The command ``cmd[k]`` is held over [kT, (k+1)T); the force follows it ``delay`` later
    through ``tau dF/dt = cmd - F`` (both exact, as in the simulator). Returns the interval
    means, which is what the velocity increment of interval k integrates. Before the start
    the command is taken as ``cmd[0]`` (a settled force).
    """
    c = np.asarray(cmd, dtype=np.float64)
    m = math.floor(delay / period + 1e-9)
    r = delay - m * period
    r = 0.0 if r <= 1e-9 * period else r
    pad = np.concatenate([np.full(m + 1, c[0]), c])
    c2 = pad[1:len(c) + 1]  # command in force after the switch (k - m)
    c1 = pad[:len(c)]  # command before the switch (k - m - 1)
    if tau <= 0.0:
        out: FloatArray = (c1 * r + c2 * (period - r)) / period
        return out
    a1, a2 = math.exp(-r / tau), math.exp(-(period - r) / tau)
    drive = (1.0 - a1) * a2 * c1 + (1.0 - a2) * c2
    z0 = c[0]
    z_next = lfilter([1.0], [1.0, -a1 * a2], drive, zi=[a1 * a2 * z0])[0]
    z = np.concatenate([[z0], z_next[:-1]])  # force at the start of each interval
    z_mid = c1 + (z - c1) * a1
    integral = c1 * r + (z - c1) * tau * (1 - a1) + c2 * (period - r) \
        + (z_mid - c2) * tau * (1 - a2)
    res: FloatArray = integral / period
    return res


def smooth_sign(v: FloatArray, smoothing: float = SIGN_SMOOTHING_MPS) -> FloatArray:
    """sign(v) regularised as tanh(v / smoothing), the simulator's convention."""
    out: FloatArray = np.tanh(np.asarray(v) / smoothing)
    return out


def smooth_abs(v: FloatArray, smoothing: float) -> FloatArray:
    """smoothing * log cosh(v / smoothing): |v| rounded off, the antiderivative of tanh."""
    z = np.abs(np.asarray(v, dtype=np.float64)) / smoothing
    out: FloatArray = smoothing * (z + np.log1p(np.exp(-2.0 * z)) - math.log(2.0))
    return out


def interval_friction(v_lo: FloatArray, v_hi: FloatArray, smoothing: float,
                      stribeck_mps: float = 0.0) -> FloatArray:
    """Mean of sign(v) (or of the Stribeck hump exp(-(v/vs)²) sign(v)) over an interval.

    The speed is taken linear between its values at the interval's ends, so the mean is
    ``(G(v_hi) - G(v_lo)) / (v_hi - v_lo)`` with G the antiderivative: ``smooth_abs`` for
    Coulomb, ``sqrt(pi)/2 vs erf(smooth_abs/vs)`` for Stribeck. A reversal inside an interval
    then counts for the fraction of the interval spent on each side, as the simulator's
    force does, instead of switching at the sample.
    """
    def anti(v: FloatArray) -> FloatArray:
        s = smooth_abs(v, smoothing)
        if stribeck_mps <= 0:
            return s
        out: FloatArray = 0.5 * math.sqrt(math.pi) * stribeck_mps * erf(s / stribeck_mps)
        return out

    mid = 0.5 * (v_lo + v_hi)
    point = smooth_sign(mid, smoothing)
    if stribeck_mps > 0:
        point = point * np.exp(-((mid / stribeck_mps) ** 2))
    dv = v_hi - v_lo
    small = np.abs(dv) < 1e-6 * smoothing
    safe = np.where(small, 1.0, dv)
    out: FloatArray = np.where(small, point, (anti(v_hi) - anti(v_lo)) / safe)
    return out


def travel_gain(v: FloatArray, period: float, wavenumber: float, mode: str) -> FloatArray:
    """Gain of averaging sin(2π κ x) over the travel of one equation instant.

    The force a position-periodic effect exerts varies within a sample interval as the
    mover travels Δx = v T; its mean over the interval is the value at the midpoint times
    sinc(κ Δx) (x linear in time). Position-mode instants average two intervals with
    triangular weights, whose gain is sinc².
    """
    g = np.asarray(np.sinc(wavenumber * v * period), dtype=np.float64)
    out: FloatArray = g if mode == "speed" else g * g
    return out


def sign_width(noise_std: float, base: float = SIGN_SMOOTHING_MPS) -> float:
    """Width of E[sign(v) | smoothed v]: the tanh width and the speed noise combined.

    tanh(x/w) matches erf(x/(sqrt(2) s)) for w = sqrt(pi/2) s = 1.2533 s; widths add in
    quadrature. Without this, noise makes sign(v) wrong near v = 0 and a spurious
    low-speed (Stribeck-like) term appears.
    """
    return math.hypot(base, math.sqrt(math.pi / 2.0) * noise_std)


def interval_effects(plant: Plant, x: FloatArray, v: FloatArray, v_lo: FloatArray,
                     v_hi: FloatArray, force: FloatArray, period: float, mode: str,
                     prior: SpeedPrior) -> FloatArray:
    """Interval means of :func:`pmsm_sysid.core.physics.motor.effects_force` for ``plant``
    (friction calibrated for the speed noise with ``prior``, :mod:`.calibration`)."""
    total = np.zeros(len(x))
    cog = plant.cogging
    if cog is not None:
        terms = [(1, cog.amplitude_n, cog.phase_rad)]
        terms += [(h.order, h.amplitude_n, h.phase_rad) for h in cog.harmonics]
        for order, amp, phase in terms:
            kappa = order / cog.pitch_m
            total += amp * travel_gain(v, period, kappa, mode) * np.sin(
                2 * math.pi * kappa * x + phase)
    cf, sf = plant.coulomb_friction, plant.stribeck_friction
    if cf is not None:
        total += cf.amplitude_n * calibrated_friction(prior, v_lo, v_hi, cf.smoothing_mps)
    if sf is not None:
        total += sf.static_n * calibrated_friction(prior, v_lo, v_hi, sf.smoothing_mps,
                                                   sf.velocity_mps)
    if plant.force_offset is not None:
        total += plant.force_offset.amplitude_n
    rip = plant.thrust_ripple
    if rip is not None:
        kappa = 1.0 / rip.pitch_m
        total -= rip.relative * travel_gain(v, period, kappa, mode) * np.sin(
            2 * math.pi * kappa * x + rip.phase_rad) * force
    if plant.spring is not None:
        total += plant.spring.stiffness_n_per_m * x
    return total
