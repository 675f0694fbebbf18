"""Is the thrust a feedback of the measurements? (Closed loop, as under a position loop.)

Under feedback the thrust at t_k answers the measurement taken at t_k, sensor noise
included; open loop it is set without looking at it. The equation error treats the two
differently (:mod:`.kinematics`: acceleration source and instruments; :mod:`.fit`: which
effects are searched), so :func:`feedback_z` scores the evidence.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..recording.signals import Recording
from ..recording.spans import Parts, as_parts
from .zerophase import butter_sos, sosfiltfilt

FloatArray = NDArray[np.float64]

FEEDBACK_Z = 4.0


FEEDBACK_LAGS = 8


def _past(sig: FloatArray, p: int) -> FloatArray:
    """Columns sig[k-1], ..., sig[k-p] for k = p .. N-1."""
    win = np.lib.stride_tricks.sliding_window_view(sig, p + 1)
    out: FloatArray = win[:, :-1][:, ::-1]
    return out


def _innovation(sig: FloatArray, past: FloatArray) -> FloatArray:
    """What of sig[k] the past does not predict (least squares, with a constant)."""
    X = np.column_stack([np.ones(len(past)), past])
    scale = np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    coef = np.linalg.lstsq(X / scale, sig, rcond=None)[0]
    out: FloatArray = sig - (X / scale) @ coef
    return out


def feedback_z(rec: Parts) -> float:
    """Evidence that the thrust is a feedback of the measurements (a z-score).

    Under feedback the thrust at t_k answers the measurement taken at t_k, noise included
    (a D-term to the speed noise, a P-term to the position noise); open loop it is set
    without looking at it. Two views of that must agree (the smaller z is returned):

    * the new part of the thrust (what its own past and the measurements' past, 8 samples,
      do not predict) against the new part of the speed or position (sensor noise, process
      force): open loop the motion answers the thrust a sample later, in the past of both,
      so a held random input (PRBS, APRBS) is not taken for a loop -- but a noisy thrust
      sensor in that past makes both predictions err together;
    * the thrust against the speed or position above 0.3 fs, where a servo's motion has no
      power: immune to thrust-sensor noise, but the speed's physical answer to the edges of
      a held random input shows there too.

    Above ``FEEDBACK_Z`` the recording is treated as closed loop. Parts of a recording are
    pooled: each part's innovations (and high band) are taken within it, then correlated
    together.
    """
    p = FEEDBACK_LAGS
    parts = [r for r in as_parts(rec) if len(r) >= 10 * p]
    if not parts:
        return 0.0
    best = 0.0
    for which in range(1 if parts[0].speed_derived else 2):
        pairs = [_innovations(r, which) for r in parts]
        best = max(best, _corr_z(np.concatenate([e for e, _ in pairs]),
                                 np.concatenate([e for _, e in pairs])))
    return min(best, _high_band_z(parts))


def _innovations(rec: Recording, which: int) -> tuple[FloatArray, FloatArray]:
    """New parts of the thrust and of the position (0) or speed (1) given 8 past samples."""
    p = FEEDBACK_LAGS
    f = np.asarray(rec.thrust, dtype=np.float64)
    s = np.asarray(rec.position if which == 0 else rec.speed, dtype=np.float64)
    past = np.hstack([_past(f, p), _past(s, p)])
    return _innovation(f[p:], past), _innovation(s[p:], past)


def _corr_z(a: FloatArray, b: FloatArray, centre: bool = False) -> float:
    """|correlation|·sqrt(N) of two equally long series."""
    if centre:
        a, b = a - a.mean(), b - b.mean()
    den = float(np.std(a) * np.std(b))
    return abs(float(np.mean(a * b)) / den) * math.sqrt(len(a)) if den > 0 else 0.0


def high_band(sig: FloatArray, fs: float) -> FloatArray:
    """``sig`` above 0.3 fs (its 20 samples of filter start-up at each end left out)."""
    hp = butter_sos(4, 0.3 * fs, fs, "highpass")
    out: FloatArray = sosfiltfilt(hp, sig)[20:-20]
    return out


def _high_band_z(parts: list[Recording]) -> float:
    """|correlation|·sqrt(N) of the thrust with the speed or position above 0.3 fs."""
    fs = parts[0].sample_rate_hz
    f = np.concatenate([high_band(r.thrust, fs) for r in parts])
    return max(_corr_z(f, np.concatenate([high_band(getattr(r, name), fs) for r in parts]),
                       centre=True) for name in ("speed", "position"))


__all__ = ["FEEDBACK_LAGS", "FEEDBACK_Z", "feedback_z", "high_band"]
