"""Per-window features the change detector watches (see :mod:`.tracker`): the input's
strongest line, the model's H1 there (Eq. 7 of Liu et al. 2005), the output's harmonic content
and the free-run error of earlier models on the newest samples.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, PmsmSysidError
from ..frequency.gfrf import Gfrf
from ..terms.model import NarxModel
from ..validation.correlation import fit_metrics
from ..validation.prediction import simulate

FloatArray = NDArray[np.float64]

__all__ = [
    "INPUT_HARMONICS_MAX_DB", "best_newest_error", "dominant_frequency", "h1_features",
    "harmonics_db", "newest_error", "plant_harmonics_db", "wrap_phase",
]


def dominant_frequency(u: FloatArray) -> float:
    """Strongest non-d.c. line of ``u`` in cycles/sample (its FFT bin)."""
    spec = np.abs(np.fft.rfft(np.asarray(u, dtype=np.float64) - np.mean(u)))
    if len(spec) < 2 or not spec[1:].max() > 0:
        raise DataError("the input has no excitation (constant over the window)")
    return float((1 + int(np.argmax(spec[1:]))) / len(u))


def h1_features(model: NarxModel, f_norm: float) -> dict[str, float]:
    """Gain (dB) and phase (rad) of the model's H1 (Eq. 7 of Liu et al. 2005) at ``f_norm``."""
    try:
        h = complex(Gfrf.from_model(model).h1(np.array([f_norm]))[0])
    except PmsmSysidError:
        return {"h1_gain_db": math.nan, "h1_phase_rad": math.nan}
    if not (abs(h) > 0 and math.isfinite(abs(h))):  # no linear input path: no H1 to watch
        return {"h1_gain_db": math.nan, "h1_phase_rad": math.nan}
    return {"h1_gain_db": 20 * math.log10(abs(h)), "h1_phase_rad": math.atan2(h.imag, h.real)}


def wrap_phase(phi: float) -> float:
    """``phi`` wrapped to (-pi, pi] (NaN stays NaN)."""
    return phi if not math.isfinite(phi) else math.pi - (math.pi - phi) % (2 * math.pi)


def harmonics_db(y: FloatArray, f0: float, n_harmonics: int = 4) -> float:
    """Output energy at 2..(n+1) x ``f0`` over the energy at ``f0`` (dB).

    Least-squares fit of a mean plus sine/cosine pairs at h*f0 (cycles/sample), h = 1..n+1
    below Nyquist, so any length of ``y`` works (no FFT bin leakage). NaN if ``y`` has no
    component at ``f0``.
    """
    y = np.asarray(y, dtype=np.float64)
    hs = [h for h in range(1, n_harmonics + 2) if h * f0 < 0.5]
    k = np.arange(len(y), dtype=np.float64)
    cols = [np.ones_like(k)]
    for h in hs:
        cols += [np.cos(2 * np.pi * h * f0 * k), np.sin(2 * np.pi * h * f0 * k)]
    coef = np.linalg.lstsq(np.stack(cols, axis=1), y, rcond=None)[0]
    power = coef[1::2] ** 2 + coef[2::2] ** 2
    if len(power) < 2 or not power[0] > 0:
        return math.nan
    return float(10 * np.log10(max(float(power[1:].sum()), 1e-300) / power[0]))


#: The output's harmonic content is the plant's only when the input holds (almost) none of its
#: own at those harmonics: input harmonics (:func:`harmonics_db` of the input) at most this.
#: Measured over 120 s of each packaged excitation (1000-sample windows, hop 250): the paper's
#: tones stay below -44 dB (-280 dB once faded in); every window of multisine, PRBS, APRBS
#: and broadband is above -36 dB (APRBS -14 to +2 dB: its output "harmonics" are its own
#: input's, window by window); chirp windows fall on both sides, each phase of the sweep always
#: on the same one. A 5 N noisy thrust reading of a 10 N tone reads about -25 dB (not
#: observed), of a 50 N tone about -38 dB (observed in most windows).
INPUT_HARMONICS_MAX_DB = -40.0


def plant_harmonics_db(y: FloatArray, u: FloatArray) -> float:
    """:func:`harmonics_db` of the output ``y`` at the input's strongest line, NaN (no
    observation) when the input ``u`` itself holds more than
    :data:`INPUT_HARMONICS_MAX_DB` at those harmonics: then they are the excitation's."""
    f0 = dominant_frequency(u)
    own = harmonics_db(u, f0)
    if not own <= INPUT_HARMONICS_MAX_DB:  # also NaN: no line, or harmonics above Nyquist
        return math.nan
    return harmonics_db(y, f0)


def best_newest_error(models: list[NarxModel], y: FloatArray, u: FloatArray,
                      hop: int) -> float:
    """The smallest :func:`newest_error` of ``models`` (the last models of the stream): one
    odd fit among them does not score, a plant change in the newest samples defeats all."""
    errors = [newest_error(m, y, u, hop) for m in models]
    finite = [e for e in errors if not math.isnan(e)]
    return min(finite) if finite else math.nan


def newest_error(model: NarxModel, y: FloatArray, u: FloatArray, hop: int) -> float:
    """NRMSE of ``model``'s free run (Eq. 12, over all of y) on the last ``hop`` samples;
    inf if the free run diverges, NaN if those samples are constant."""
    run = simulate(model, u, y[:model.max_lag])
    if run.diverged:
        return math.inf
    try:
        return fit_metrics(y[-hop:], run.y[-hop:]).nrmse
    except DataError:
        return math.nan
