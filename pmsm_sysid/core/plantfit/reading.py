"""The thrust reading's own noise, and how far from the instant it keeps the thrust.

A thrust estimated from phase current carries white noise at its own instant; that noise
is in the residual too (:mod:`.instruments`). :func:`reading_noise` reads it from the
recording, :func:`reading_gap` says whether it would move the mass by a standard error,
and :func:`noise_gap` how many samples the parallel filter needs between a thrust sample
and the instant to keep the two apart.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch
from scipy.stats import chi2

from ..recording.spans import Parts, as_parts
from .kinematics import EquationData
from .zerophase import sosfiltfilt

FloatArray = NDArray[np.float64]

GAP_TAIL = 0.1  # filter autocorrelation (sum of |rho|) left beyond the gap
FLOOR_QUANTILE = 0.1  # the quietest tenth of the thrust spectrum is its noise floor


def noise_gap(sos: FloatArray) -> int:
    """Samples between a thrust sample and the residual's instant for the zero-phase filter
    to keep them apart: the filtered noise of two samples that far apart correlates by
    less than ``GAP_TAIL`` in all (the tail of the filter's autocorrelation)."""
    imp = np.zeros(8193)
    imp[4096] = 1.0
    h = sosfiltfilt(sos, imp)
    spec = np.abs(np.fft.rfft(h, 2 * len(h))) ** 2
    ac = np.fft.irfft(spec)[:len(h)]
    ac = np.abs(ac / ac[0])
    tail = np.cumsum(ac[::-1])[::-1]
    return int(np.argmax(tail < GAP_TAIL))


def reading_noise(rec: Parts, closed_loop: bool = False) -> float:
    """Variance (N²) of the white noise on the thrust reading (:func:`white_floor`), pooled
    over the parts of a recording (each part read on its own, weighted by its length).

    Under feedback the controller answers the sensors' noise at once -- a white part of
    the thrust that is applied, not a reading's error -- so that answer is taken out
    first: the gains with which the thrust's sample-to-sample changes follow those of the
    measured speed and position (where their noise dominates), times the measurements.
    """
    parts = as_parts(rec)
    thrusts = [np.asarray(p.thrust, dtype=np.float64) for p in parts]
    if closed_loop:
        states = [np.column_stack([p.speed, p.position]) for p in parts]
        dX = np.concatenate([np.diff(X, axis=0) for X in states])
        dF = np.concatenate([np.diff(f) for f in thrusts])
        scale = np.maximum(np.linalg.norm(dX, axis=0), 1e-300)
        gains = np.linalg.lstsq(dX / scale, dF, rcond=None)[0] / scale
        thrusts = [f - X @ gains for f, X in zip(thrusts, states, strict=True)]
    fs = parts[0].sample_rate_hz
    sizes = [len(f) for f in thrusts]
    return float(np.average([white_floor(f, fs) for f in thrusts], weights=sizes))


def white_floor(thrust: FloatArray, fs: float) -> float:
    """Variance (N²) of the white noise on a thrust signal, read two ways, the smaller
    kept (each only overstates it):

    * the floor of its spectrum: the quietest tenth of the Welch periodogram (a multisine,
      a chirp or a tone leaves most of the band to the noise), corrected for the spread
      of the periodogram;
    * its variogram ``γ(j) = E[(F_k+j - F_k)²]/2`` at lags 1-4 extrapolated to lag 0 (a
      cubic): white noise adds its variance at every lag but 0, while a held input
      (PRBS, APRBS) or a smooth one is a low-order polynomial near 0.

    A thrust with power all across the band (a white excitation) is read as all noise: its
    sample-to-sample part cannot be told from a reading's noise.
    """
    f = np.asarray(thrust, dtype=np.float64) - float(np.mean(thrust))
    n = len(f)
    if n < 64:
        return 0.0
    g = [0.5 * float(np.mean((f[j:] - f[:-j]) ** 2)) for j in (1, 2, 3, 4)]
    from_variogram = 4.0 * g[0] - 6.0 * g[1] + 4.0 * g[2] - g[3]
    nper = int(min(512, max(32, n // 8)))
    _, p = welch(f, fs=fs, nperseg=nper)
    segments = max(1, 2 * n // nper - 1)
    dof = 2.0 * segments
    spread = float(chi2.ppf(FLOOR_QUANTILE, dof) / dof)
    from_floor = float(np.quantile(p[1:], FLOOR_QUANTILE)) / spread * fs / 2.0
    return max(0.0, min(from_variogram, from_floor))


def reading_gap(noise_var: float, data: EquationData) -> int:
    """The gap to keep between the thrust and the instant (0: the reading is clean enough).

    A reading noise of variance σ² biases a regression on the same-instant thrust by about
    σ² ‖h‖² / var(L F) of the mass (h the parallel filter), against a standard error of
    about rms(L r) / (rms(L F) √n): above one standard error the gap is kept.
    """
    if noise_var <= 0.0:
        return 0
    imp = np.zeros(8193)
    imp[4096] = 1.0
    gain = float(np.sum(sosfiltfilt(data.sos, imp) ** 2))
    lf = data.project(data.force - float(np.mean(data.force)))
    rms_f, rms_y = float(np.std(lf)), float(np.std(data.y))
    if rms_f <= 0.0 or rms_y <= 0.0:
        return 0
    t_bias = noise_var * gain * math.sqrt(data.n) / (rms_f * rms_y)
    return noise_gap(data.sos) if t_bias > 1.0 else 0


__all__ = ["noise_gap", "reading_gap", "reading_noise", "white_floor"]
