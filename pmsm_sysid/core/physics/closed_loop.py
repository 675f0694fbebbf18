"""A position loop around the simulator: recordings whose thrust is a controller's output.

Real axes (the EMPS rig among them) are recorded under position control, so the thrust is
what a controller needed to follow a reference: friction, offsets and cogging are fought
by the loop and barely show in the position, but they are all in the thrust. This module
closes a PID loop around :class:`~pmsm_sysid.core.physics.motor.MotorSimulator` with the recordings'
timing: the controller reads position and speed at t_k and its output is held over
[t_k, t_k+1). An optional ``disturbance`` force acts on the mover without being recorded
(an unmodelled, unmeasured force).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import DataError
from ..recording.signals import Recording
from .motor import MotorSimulator
from .plant import Plant, dump_plant

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PositionLoop:
    """PID position controller ``F = kp e + kd de/dt + ki ∫e`` on the measured state."""

    kp_n_per_m: float
    kd_n_s_per_m: float
    ki_n_per_m_s: float = 0.0

    @classmethod
    def for_bandwidth(cls, plant: Plant, bandwidth_hz: float, damping: float = 0.7,
                      integral_fraction: float = 0.1) -> PositionLoop:
        """Gains placing the loop's poles at ``bandwidth_hz`` with the given damping."""
        w = 2.0 * math.pi * bandwidth_hz
        m = plant.mass_kg
        kd = max(2.0 * damping * w * m - plant.viscous_n_per_mps, 0.0)
        kp = m * w * w
        return cls(kp, kd, integral_fraction * kp * w)


def reference_trajectory(n: int, fs: float, amplitudes_m: tuple[float, ...],
                         freqs_hz: tuple[float, ...], fade_s: float = 0.5) -> FloatArray:
    """Sum of sines (raised-cosine fade-in), the position the loop is asked to follow."""
    t = np.arange(n) / fs
    x = sum((a * np.sin(2.0 * math.pi * f * t + 0.7 * i)
             for i, (a, f) in enumerate(zip(amplitudes_m, freqs_hz, strict=True))),
            np.zeros(n))
    fade = np.where(t < fade_s, 0.5 * (1.0 - np.cos(np.pi * t / fade_s)), 1.0)
    out: FloatArray = x * fade
    return out


def run_closed_loop(plant: Plant, reference: ArrayLike, loop: PositionLoop, seed: int = 0,
                    disturbance: ArrayLike | None = None,
                    injection: ArrayLike | None = None) -> Recording:
    """Simulate the loop following ``reference`` (m, one value per sample).

    ``injection`` (N per sample) is added to the controller's output and recorded with it
    (an identification signal injected into the loop); the recorded thrust carries the
    plant's thrust-sensor noise (``noise.thrust_std``) as in open loop.
    """
    xr = np.asarray(reference, dtype=np.float64)
    if xr.ndim != 1 or len(xr) < 3 or not np.isfinite(xr).all():
        raise DataError("the reference must be a finite 1-D array of at least 3 samples")
    d = np.zeros(len(xr)) if disturbance is None else np.asarray(disturbance, dtype=np.float64)
    if d.shape != xr.shape:
        raise DataError(f"disturbance has {d.shape} samples, reference {xr.shape}")
    inj = np.zeros(len(xr)) if injection is None else np.asarray(injection, dtype=np.float64)
    if inj.shape != xr.shape or not np.isfinite(inj).all():
        raise DataError(f"injection must be finite with {len(xr)} samples, got {inj.shape}")
    fs = plant.sample_rate_hz
    vr = np.gradient(xr) * fs
    sim = MotorSimulator(plant, seed=seed, x0=float(xr[0]))
    n = len(xr)
    thrust, speed, position = [], [], []
    kp, kd, ki = loop.kp_n_per_m, loop.kd_n_s_per_m, loop.ki_n_per_m_s
    integral = 0.0
    # Python floats per sample: the same IEEE arithmetic as numpy scalars, cheaper
    for xr_k, vr_k, inj_k, d_k in zip(xr.tolist(), vr.tolist(), inj.tolist(), d.tolist(),
                                      strict=True):
        v_k, x_k = sim.measure()
        speed.append(v_k)
        position.append(x_k)
        err = xr_k - x_k
        integral += err / fs
        command = kp * err + kd * (vr_k - v_k) + ki * integral + inj_k
        thrust.append(sim.measured_thrust(command))
        sim.advance(command + d_k)
    meta = {"plant": dump_plant(plant), "seed": str(seed), "simulator": "pmsm_sysid.physics",
            "control": f"PID kp={loop.kp_n_per_m:.6g} kd={loop.kd_n_s_per_m:.6g} "
                       f"ki={loop.ki_n_per_m_s:.6g}"}
    return Recording(t=np.arange(n) / fs, thrust=np.array(thrust, dtype=np.float64),
                     speed=np.array(speed, dtype=np.float64),
                     position=np.array(position, dtype=np.float64), sample_rate_hz=fs,
                     source="closed-loop simulation", meta=meta)
