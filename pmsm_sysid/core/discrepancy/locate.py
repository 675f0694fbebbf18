"""Where a force residual lives: over time, position, velocity and frequency.

Each axis gets a generic, physics-free basis -- 16 equal time windows, 16 position bins,
16 velocity bins (quantiles), and a sin/cos pair at the strongest spectral line -- and the
basis is put to the same prewhitened nested F-test as the library effects (:mod:`.stats`),
against whatever model is already fitted. ``share`` is the fraction of the residual energy
the basis explains. Run on the nominal residual this says where the mismatch is; run on the
residual of the final model it finds what no library effect explained (``unexplained``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .kinematics import EquationData, thinned, thinned_times
from .stats import lstsq, nested_f_test

FloatArray = NDArray[np.float64]

N_BINS = 16
AXES = ("time", "position", "velocity", "frequency")


@dataclass(frozen=True)
class AxisFinding:
    """How much of a residual one axis's generic basis explains, and how surely."""

    axis: str
    share: float
    significance: float
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"axis": self.axis, "share": self.share, "significance": self.significance,
                **self.details}


def _bins(values: FloatArray, n_bins: int, quantile: bool) -> tuple[FloatArray, FloatArray]:
    """Indicator columns of ``values`` in n bins, and the bin edges."""
    if quantile:
        edges = np.unique(np.quantile(values, np.linspace(0, 1, n_bins + 1)))
    else:
        edges = np.linspace(values.min(), values.max(), n_bins + 1)
    idx = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
    ind = np.zeros((len(values), len(edges) - 1))
    ind[np.arange(len(values)), idx] = 1.0
    keep = ind.sum(axis=0) > 0
    return ind[:, keep], edges


def _bin_means(r: FloatArray, ind: FloatArray) -> FloatArray:
    out: FloatArray = (ind.T @ r) / np.maximum(ind.sum(axis=0), 1.0)
    return out


def _time_details(r: FloatArray, t: FloatArray, ind: FloatArray) -> dict[str, Any]:
    rms = np.sqrt(_bin_means(r * r, ind))
    slope = float(np.polyfit(t - t[0], r, 1)[0]) if len(t) > 2 else 0.0
    med = float(np.median(rms))
    bursts = [int(i) for i in np.flatnonzero(rms > 2.0 * med)]
    return {"rms_n": float(np.sqrt(np.mean(r * r))), "drift_n_per_s": slope,
            "window_rms_n": rms.tolist(), "burst_windows": bursts,
            "window_s": float((t[-1] - t[0]) / ind.shape[1])}


def _velocity_details(r: FloatArray, v: FloatArray) -> dict[str, Any]:
    """Jump across v = 0 and slope with speed, by a sign + linear fit on each side."""
    X = np.column_stack([np.ones_like(v), np.sign(v), v])
    beta, _ = lstsq(X, r)
    return {"jump_at_zero_n": 2.0 * float(beta[1]), "slope_n_per_mps": float(beta[2]),
            "speed_range_mps": [float(v.min()), float(v.max())]}


def _sincos(t: FloatArray, f: float) -> FloatArray:
    return np.column_stack([np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)])


def _strongest_line(r: FloatArray, t: FloatArray, fs: float) -> tuple[float, float]:
    """Frequency (Hz) of the strongest spectral line above 0 Hz, and its power share.

    The peak of the periodogram is only good to half a bin (1/(2T)), which over T seconds
    is a phase error of up to π: the frequency is refined by least squares over ±1 bin.
    """
    rc = r - r.mean()
    spec = np.abs(np.fft.rfft(rc, 8 * len(r))) ** 2  # zero-padded: 1/8 bin steps
    freqs = np.fft.rfftfreq(8 * len(r), 1.0 / fs)
    k = int(np.argmax(spec[8:])) + 8
    bin_hz = fs / len(r)
    tt = t - t[0]
    best = (0.0, float(freqs[k]))
    for f in np.linspace(freqs[k] - bin_hz, freqs[k] + bin_hz, 41):
        if f <= 0:
            continue
        _, e = lstsq(_sincos(tt, float(f)), rc)
        best = max(best, (float(rc @ rc - e @ e), float(f)))
    return best[1], best[0] / max(float(rc @ rc), 1e-300)


def scan_axes(data: EquationData, y: FloatArray, base: FloatArray,
              n_bins: int = N_BINS, total: float | None = None,
              null_whitening: bool = False) -> list[AxisFinding]:
    """Axis findings for residual target ``y`` beyond the columns ``base`` (module doc).

    Shares are fractions of ``total`` (default: the energy of ``y``). ``null_whitening``
    (see :func:`.stats.nested_f_test`) keeps the bin tests at their level when ``y`` beyond
    ``base`` is noise, as it is when looking for what the final model left unexplained;
    describing a raw mismatch, where ``y`` is mostly the effect, it would whiten the effect
    away.
    """
    t = thinned_times(data)
    x = thinned(data, data.x)
    v = thinned(data, data.v)
    _, r = lstsq(base, y)
    yy = float(y @ y) if total is None else total
    out = []
    bases = {"time": _bins(t, n_bins, False)[0], "position": _bins(x, n_bins, True)[0],
             "velocity": _bins(v, n_bins, True)[0]}
    n_freq = len(r) // 2
    for axis, ind in bases.items():
        test = nested_f_test(y, base, ind, null_whitening=null_whitening)
        _, r1 = lstsq(np.hstack([base, ind]), y)
        share = float(r @ r - r1 @ r1) / yy
        details: dict[str, Any] = {}
        if axis == "time":
            details = _time_details(r, t, ind)
        elif axis == "position":
            details = {"bin_means_n": _bin_means(r, ind).tolist(),
                       "position_range_m": [float(x.min()), float(x.max())]}
        else:
            details = _velocity_details(r, v)
        out.append(AxisFinding(axis, share, -test.corrected_log10_p(len(AXES)), details))
    f0, line_share = _strongest_line(r, t, data.sample_rate_hz)
    cols = _sincos(t - t[0], f0)
    test = nested_f_test(y, base, cols)
    _, r1 = lstsq(np.hstack([base, cols]), y)
    out.append(AxisFinding("frequency", float(r @ r - r1 @ r1) / yy,
                           -test.corrected_log10_p(len(AXES) - 1 + n_freq),
                           {"line_hz": f0, "line_power_share": line_share}))
    return out
