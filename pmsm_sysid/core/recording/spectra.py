"""Welch power spectra and peak finding with NumPy alone.

:func:`welch` and :func:`find_peaks` give what :func:`scipy.signal.welch` and
:func:`scipy.signal.find_peaks` give for the cases the package uses: a periodic Hann
window, half-overlapping segments, a one-sided density averaged by the mean; the local
maxima (the middle of a flat top) and their topographic prominences. They exist because
importing ``scipy.signal`` costs about half a second of CPU (it imports ``scipy.stats``
too), and the live identifier's and GFRF node's worker processes need nothing else of it:
their fork server imports less, and a run starts lighter.

test_spectra checks both against SciPy: :func:`find_peaks` bit for bit, :func:`welch` to
rounding (the FFT and the scaling are NumPy's, not the short-time FFT SciPy routes
through).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def hann(n: int) -> FloatArray:
    """The periodic Hann window of ``n`` samples (``scipy.signal.get_window('hann', n)``)."""
    fac = np.linspace(-np.pi, np.pi, n + 1)
    out: FloatArray = (0.5 + 0.5 * np.cos(fac))[:-1]
    return out


def welch(x: NDArray[np.float64], fs: float = 1.0, nperseg: int = 256,
          detrend: bool = True) -> tuple[FloatArray, FloatArray]:
    """(frequencies, one-sided power spectral density) of ``x``: periodic Hann segments of
    ``nperseg`` samples overlapping by half, each without its mean when ``detrend``, the
    squared magnitudes averaged -- ``scipy.signal.welch(x, fs, nperseg=nperseg,
    detrend='constant' if detrend else False)``. ValueError unless 2 <= nperseg <= len(x)."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1 or not 2 <= nperseg <= len(x):
        raise ValueError(f"need a 1-D signal of at least nperseg={nperseg} samples, "
                         f"got shape {x.shape}")
    step = nperseg - nperseg // 2
    count = (len(x) - nperseg // 2) // step
    seg = x[np.arange(count)[:, None] * step + np.arange(nperseg)]
    if detrend:
        seg = seg - seg.mean(axis=1, keepdims=True)
    win = hann(nperseg)
    spec = np.fft.rfft(seg * win, axis=1)
    p = (spec.real ** 2 + spec.imag ** 2) / (fs * float(np.sum(win * win)))
    p[:, 1:None if nperseg % 2 else -1] *= 2.0  # the negative frequencies folded in
    psd: FloatArray = p.mean(axis=0)
    freqs = np.asarray(np.fft.rfftfreq(nperseg, 1.0 / fs), dtype=np.float64)
    return freqs, psd


def _local_maxima(x: FloatArray) -> IntArray:
    """Indices of the samples higher than both neighbours (the middle of a flat top, left
    of centre for an even one); never the first or the last sample."""
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change - 1, [len(x) - 1]))
    level = x[starts]
    peak = np.zeros(len(starts), dtype=bool)
    peak[1:-1] = (level[1:-1] > level[:-2]) & (level[1:-1] > level[2:])
    out: IntArray = (starts[peak] + ends[peak]) // 2
    return out


def _reach(x: FloatArray, i: int, step: int) -> int:
    """The first index from ``i`` (exclusive) in direction ``step`` holding a sample higher
    than ``x[i]``, or one past the end; searched in spans growing fourfold (a peak is
    usually close to a higher sample, and a whole-signal scan per peak grows as the
    signal's length times its peaks)."""
    top, span, n = x[i], 64, len(x)
    while True:
        lo, hi = (i + 1, min(i + 1 + span, n)) if step > 0 else (max(i - span, 0), i)
        higher = np.flatnonzero(x[lo:hi] > top)
        if len(higher):
            return lo + int(higher[0] if step > 0 else higher[-1])
        if (hi == n) if step > 0 else (lo == 0):
            return n if step > 0 else -1
        span *= 4


def prominences(x: FloatArray, peaks: IntArray) -> FloatArray:
    """How far each peak stands above the higher of its two bases: the lowest sample on
    each side before a higher one (or the end) -- ``scipy.signal.peak_prominences``."""
    out = np.empty(len(peaks))
    for k, i in enumerate(peaks.tolist()):
        left = float(np.min(x[_reach(x, i, -1) + 1:i + 1]))
        right = float(np.min(x[i:_reach(x, i, 1)]))
        out[k] = x[i] - max(left, right)
    return out


def find_peaks(x: NDArray[np.float64], prominence: float | None = None,
               ) -> tuple[IntArray, FloatArray]:
    """(indices, prominences) of the local maxima of ``x`` whose prominence is at least
    ``prominence`` (all with None) -- ``scipy.signal.find_peaks(x, prominence=...)``'s
    peaks and ``prominences``."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"need a 1-D signal, got shape {x.shape}")
    peaks = _local_maxima(x) if len(x) > 2 else np.zeros(0, dtype=np.intp)
    prom = prominences(x, peaks)
    if prominence is not None:
        keep = prom >= prominence
        peaks, prom = peaks[keep], prom[keep]
    return peaks, prom


__all__ = ["find_peaks", "hann", "prominences", "welch"]
