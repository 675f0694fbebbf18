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

**A noisy thrust reading** (a thrust estimated from phase current) breaks that: its noise
n_k is in the residual ``r = F_rec - M a - B v`` at instant k, and an instrument built
from the same thrust sample carries n_k too -- the mass came out 13 % heavy on a nominal
plant. The zero-phase parallel filter spreads each noise sample over its neighbours, so a
thrust sample is free of the residual's noise only when it lies further away than the
filter's memory (:func:`.reading.noise_gap`). When the reading's own noise
(:func:`.reading.reading_noise`) would move the mass by a standard error, the instruments are
built from the thrust at least that gap away -- before and after the instant open loop,
before it under feedback -- and every other regressor made of the thrust (its
derivative for a lag, the thrust times a position wave for a ripple) uses the thrust as
those neighbours predict it (:func:`interpolated`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from .zerophase import sosfiltfilt

FloatArray = NDArray[np.float64]

POLE_FACTORS = (0.5, 1.0, 2.0)  # mechanical time constants M/B tried, relative to nominal
TAPS = 8  # thrust samples on each side of the gap (interpolation across it)


def _shift(x: FloatArray, s: int) -> FloatArray:
    """x delayed by s samples (s < 0: advanced), zeros where nothing is known."""
    if s == 0:
        return x
    out = np.zeros_like(x)
    if s > 0:
        out[s:] = x[:-s]
    else:
        out[:s] = x[-s:]
    return out


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


def _paired(cmd: FloatArray, n: int, mode: str) -> FloatArray:
    out: FloatArray = cmd[:n] if mode == "speed" else 0.5 * (cmd[:n] + cmd[1:n + 1])
    return out


def _taps(cmd: FloatArray, gap: int, future: bool) -> list[FloatArray]:
    """The thrust ``gap`` .. ``gap + TAPS - 1`` samples before (and after) each sample."""
    out = []
    for j in range(gap, gap + TAPS):
        out.append(_shift(cmd, j))
        if future:
            out.append(_shift(cmd, -j))
    return out


def _columns(cmd: FloatArray, period: float, mass: float, viscous: float, mode: str,
             n: int, lag: int, future: bool, v0: float = 0.0) -> FloatArray:
    """Instrument columns at the ``n`` equation instants of ``mode`` (linear in ``cmd``
    but for the constant and the start from ``v0``)."""
    delayed = _shift(cmd, lag)
    cols = [np.ones(n)]
    for vs in _responses(delayed, period, mass, viscous, v0 if lag == 0 else 0.0):
        v, a = _kinematics(vs, period, mode)
        cols += [v[:n], a[:n]]
    taps = _taps(cmd, lag, future) if future else [delayed]
    cols += [_paired(c, n, mode) for c in taps]
    return np.column_stack(cols)


def _orth(Z: FloatArray) -> FloatArray:
    """Orthonormal basis of the columns of Z (numerical rank)."""
    u, sv, _ = np.linalg.svd(Z / np.maximum(np.linalg.norm(Z, axis=0), 1e-300),
                             full_matrices=False)
    out: FloatArray = u[:, sv > sv[0] * max(Z.shape) * np.finfo(float).eps]
    return out


def instrument_basis(cmd: FloatArray, period: float, mass: float, viscous: float,
                     mode: str, n: int, lag: int = 0, future: bool = False,
                     v0: float = 0.0) -> FloatArray:
    """The instruments at the ``n`` equation instants of ``mode``, orthonormal columns.

    ``lag`` > 0 builds them from the thrust ``lag`` samples earlier and more: under
    feedback the thrust answers the sensor noise at once, and a noisy thrust reading
    carries its noise at its own instant, so only a thrust older than the filter's memory
    is free of the noise in the residual. ``future`` (open loop only, where the thrust
    does not answer the motion) adds the thrust ``lag`` samples later and more, so the
    thrust at the instant is interpolated across the gap instead of predicted.
    """
    cmd = np.asarray(cmd, dtype=np.float64)
    return _orth(_columns(cmd, period, mass, viscous, mode, n, lag, future, v0))


def instrumented(cmd: FloatArray, period: float, mass: float, viscous: float, mode: str,
                 a_meas: FloatArray, v_meas: FloatArray,
                 lag: int = 0, future: bool = False) -> tuple[FloatArray, FloatArray]:
    """First-stage projections of the measured acceleration and speed on the instruments
    (:func:`instrument_basis`)."""
    q = instrument_basis(cmd, period, mass, viscous, mode, len(a_meas), lag, future,
                         float(v_meas[0]))
    return q @ (q.T @ a_meas), q @ (q.T @ v_meas)


def _leak(make: Callable[[FloatArray], FloatArray], sos: FloatArray, mode: str,
          span: int) -> FloatArray:
    """How much each column ``make`` builds from the thrust correlates, after the parallel
    filter, with the reading's noise at the instant (per unit noise variance).

    A unit impulse of noise at one sample goes through the column builder and through the
    residual (where it is the recorded thrust of its instant, paired as ``mode`` pairs
    it); both are filtered and their product summed. The columns are linear in the thrust,
    so this is the expected correlation of the filtered column with the filtered noise of
    the residual, whatever the thrust.
    """
    size = 2 * span + 4097
    imp = np.zeros(size)
    imp[size // 2] = 1.0
    cols = make(imp)
    noise = _paired(imp, len(cols), mode)
    out: FloatArray = sosfiltfilt(sos, cols, axis=0).T @ sosfiltfilt(sos, noise)
    return out


def _free_of(leak: FloatArray, scale: FloatArray) -> FloatArray:
    """Coefficient combinations (columns) that carry none of the ``leak``."""
    ell = leak / scale
    if not np.any(ell):
        return np.eye(len(ell))
    _, _, vt = np.linalg.svd(ell[None, :])
    out: FloatArray = vt[1:].T
    return out


def filtered_instruments(cmd: FloatArray, period: float, mass: float, viscous: float,
                         mode: str, n: int, lag: int, future: bool, sos: FloatArray,
                         edge: int, decimation: int) -> FloatArray:
    """Orthonormal instruments at the regression samples (filtered, trimmed, decimated),
    restricted to the combinations that do not correlate with the noise of the thrust
    reading at the instant (:func:`_leak`): the gap keeps that correlation small, the
    restriction takes out what the filter's tail leaves of it, whatever weights the first
    stage gives the samples beyond the gap."""
    cmd = np.asarray(cmd, dtype=np.float64)
    Z = _columns(cmd, period, mass, viscous, mode, n, lag, future)
    lz = sosfiltfilt(sos, Z, axis=0)[edge:n - edge:decimation]
    scale = np.maximum(np.linalg.norm(lz, axis=0), 1e-300)
    leak = _leak(lambda c: _columns(c, period, mass, viscous, mode, len(c) - 2, lag,
                                    future), sos, mode, lag + TAPS)
    leak[0] = 0.0  # the constant holds no noise
    return _orth((lz / scale) @ _free_of(leak, scale))


def interpolated(cmd: FloatArray, period: float, mass: float, viscous: float, gap: int,
                 future: bool, sos: FloatArray, mode: str) -> FloatArray:
    """The thrust of each interval as the thrust at least ``gap`` samples away predicts it
    (before and after it when ``future``), with no correlation with the reading's noise at
    the instant left after the filter (:func:`filtered_instruments`): a thrust for the
    regressors that multiply it by a function of the state."""
    cmd = np.asarray(cmd, dtype=np.float64)

    def make(c: FloatArray) -> FloatArray:
        cols = [np.ones(len(c))]
        cols += [vs[:-1] for vs in _responses(_shift(c, gap), period, mass, viscous, 0.0)]
        cols += _taps(c, gap, future)
        return np.column_stack(cols)

    C = make(cmd)
    scale = np.maximum(np.linalg.norm(C, axis=0), 1e-300)
    leak = _leak(lambda c: np.column_stack([_paired(col, len(c) - 2, mode)
                                            for col in make(c).T]), sos, mode, gap + TAPS)
    leak[0] = 0.0
    basis = (C / scale) @ _free_of(leak, scale)
    out: FloatArray = basis @ np.linalg.lstsq(basis, cmd, rcond=None)[0]
    return out


def reading_instruments(cmd: FloatArray, period: float, nominal: tuple[float, float],
                        mode: str, a: FloatArray, v: FloatArray, gap: int, closed: bool,
                        sos: FloatArray, thin: tuple[int, int],
                        ) -> tuple[FloatArray, FloatArray, FloatArray | None,
                                   tuple[FloatArray, ...] | None]:
    """The instruments of one contiguous recording: (instrumented acceleration and speed,
    the per-interval thrust a gap away predicts or None, the filtered instruments at the
    regression samples or None).

    ``nominal``: mass and viscous coefficient; ``gap`` > 0: the reading is noisy
    (:func:`.reading.reading_gap`); ``closed``: under feedback the instruments come from
    the thrust one filter memory (``thin[0]``, the edge) earlier or more; ``thin``: the
    filter's edge and decimation. Under feedback or a noisy reading the thrust in the
    regressors is predicted from the thrust at least ``gap`` away (:func:`interpolated`).
    """
    mass, viscous = nominal
    edge, decimation = thin
    lag = max(edge, gap) if closed else gap
    q = instrument_basis(cmd, period, mass, viscous, mode, len(a), lag,
                         not closed and gap > 0, float(v[0]))
    inst = None
    if gap > 0:
        inst = (filtered_instruments(cmd, period, mass, viscous, mode, len(a), lag,
                                     not closed, sos, edge, decimation),)
    fiv = None
    if gap > 0 or closed:
        fiv = interpolated(cmd, period, mass, viscous, lag, not closed, sos, mode)
    return q @ (q.T @ a), q @ (q.T @ v), fiv, inst
