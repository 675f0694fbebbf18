"""Instrumented mass and viscous regressors (errors in variables; IDIM-IV).

The mass and viscous regressors are the measured acceleration and speed. Both carry the
sensors' noise, and the acceleration also carries the process force of the same interval,
which is in the residual too: ordinary least squares then takes noise for a mass change
(it biases the mass towards zero, by the noise's share of the acceleration's variance).
The cure of the EMPS benchmark's IDIM-IV is an instrument -- a regressor built from the
thrust alone, through the nominal plant: here the speed and acceleration of the rigid
mass-damper driven by the recorded thrust (exact under zero-order hold) for three
mechanical time constants around the nominal one, the thrust itself and a constant. The
measured acceleration and speed are each replaced by their projection on these columns
(the first stage of two-stage least squares); that projection holds none of the
measurement noise and none of the process force, so the regression on it is consistent
and its F-test keeps its level on a plant with nothing wrong.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

FloatArray = NDArray[np.float64]

POLE_FACTORS = (0.5, 1.0, 2.0)  # mechanical time constants M/B tried, relative to nominal


def _responses(cmd: FloatArray, period: float, mass: float, viscous: float,
               v0: float) -> list[FloatArray]:
    """Sample speeds (N+1) of mass-dampers with time constants around M/B, from rest at v0."""
    out = []
    tau0 = mass / max(viscous, 1e-9 * mass)
    for f in POLE_FACTORS:
        alpha = math.exp(-period / (f * tau0))
        gain = (1.0 - alpha) * f * tau0 / mass  # speed gain of a held force over one period
        v = lfilter([0.0, gain], [1.0, -alpha], np.concatenate([cmd, [0.0]]))
        out.append(v + v0 * alpha ** np.arange(len(cmd) + 1))
    return out


def _kinematics(vs: FloatArray, period: float, mode: str) -> tuple[FloatArray, FloatArray]:
    """(speed, acceleration) at the equation instants of ``mode`` from sample speeds."""
    if mode == "speed":
        return 0.5 * (vs[1:-1] + vs[:-2]), np.diff(vs[:-1]) / period
    vbar = vs[:-1]  # interval means taken as sample speeds: any thrust-only column will do
    return 0.5 * (vbar[1:-1] + vbar[:-2]), np.diff(vbar[:-1]) / period


def instrumented(cmd: FloatArray, period: float, mass: float, viscous: float, mode: str,
                 a_meas: FloatArray, v_meas: FloatArray,
                 lag: int = 0) -> tuple[FloatArray, FloatArray]:
    """First-stage projections of the measured acceleration and speed on the instruments.

    ``lag`` > 0 (closed loop) builds the instruments from the thrust ``lag`` samples
    earlier: under feedback the thrust answers the sensor noise at once, so only a thrust
    older than the filter's memory is free of the noise in the residual.
    """
    n = len(a_meas)
    cmd = np.asarray(cmd, dtype=np.float64)
    if lag > 0:
        cmd = np.concatenate([np.zeros(lag), cmd[:-lag]])
    cols = [np.ones(n)]
    for vs in _responses(cmd, period, mass, viscous, float(v_meas[0]) if lag == 0 else 0.0):
        v, a = _kinematics(vs, period, mode)
        cols += [v[:n], a[:n]]
    f = cmd[:n] if mode == "speed" else 0.5 * (cmd[:n] + cmd[1:n + 1])
    cols.append(np.asarray(f, dtype=np.float64))
    Z = np.column_stack(cols)
    scale = np.maximum(np.linalg.norm(Z, axis=0), 1e-300)
    coef_a = np.linalg.lstsq(Z / scale, a_meas, rcond=None)[0]
    coef_v = np.linalg.lstsq(Z / scale, v_meas, rcond=None)[0]
    return (Z / scale) @ coef_a, (Z / scale) @ coef_v
