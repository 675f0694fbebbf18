"""What an identified model rests on: the excitation seen in the estimation data.

A NARX model is only supported by data at the frequencies the input excited. This module
summarises the estimation input's spectrum (:func:`excitation_summary`) and judges whether a
frequency feature of the model (an H1 peak, an H2/H3 ridge) is supported (:func:`judge`).

Rule (documented in docs/frequency.md):

* Spectrum: Welch PSD of the mean-removed input, Hann window, ``nperseg = min(N, 512)``,
  50 % overlap. Bins below ``1e-10 x max`` are treated as zero (numerical floor).
* Band: the central 99 % of the input power, ``[f(0.5 %), f(99.5 %)]`` of the cumulative PSD.
  If the lower edge falls within two Welch bins of 0 Hz the band starts at 0 Hz (the lowest
  bins are what the window can resolve).
* Lines: local PSD maxima within 30 dB of the largest that stand at least 20 dB above the
  median of their neighbourhood (8-24 bins either side); a line's power is the PSD summed
  over +-3 bins (the Hann main lobe). Line frequencies are refined on a zero-padded
  periodogram of the whole record.
* Tonal (``broadband = False``): at most 8 lines holding at least 90 % of the power. A
  sum of k sinusoids is exactly predicted by an AR(2k) recursion, so a model fitted to tonal
  data can place pole pairs at the tones whatever the plant is.
* Judgement of a feature at ``f``: unsupported if ``f`` is outside the band (with a tolerance
  of two Welch bins), or if the data are tonal and ``f`` lies within
  ``max(2 Welch bins, 10 % of the tone)`` of a tone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, InsufficientExcitationError
from ..recording.spectra import local_maxima, welch

FloatArray = NDArray[np.float64]

POWER_FRACTION = 0.99
NPERSEG_MAX = 512
FLOOR_REL = 1e-10
LINE_DB_OVER_LOCAL = 20.0
LINE_DB_BELOW_MAX = 30.0
LINE_HALF_WIDTH = 3
TONAL_MAX_LINES = 8
TONAL_POWER_FRACTION = 0.9
TONE_REL_TOL = 0.1


@dataclass(frozen=True)
class ExcitationSummary:
    """Spectral summary of the estimation input (see the module docstring for the rule)."""

    band_hz: tuple[float, float]
    band_norm: tuple[float, float]
    tones_hz: tuple[float, ...]
    broadband: bool
    n_lines: int
    sample_rate_hz: float
    resolution_hz: float = 0.0
    line_power_fraction: float = 0.0
    rms: float = 0.0  # of the mean-removed input, in its own unit (N for thrust)

    def to_dict(self) -> dict[str, Any]:
        return {
            "band_hz": [float(self.band_hz[0]), float(self.band_hz[1])],
            "band_norm": [float(self.band_norm[0]), float(self.band_norm[1])],
            "tones_hz": [float(f) for f in self.tones_hz],
            "broadband": bool(self.broadband),
            "n_lines": int(self.n_lines),
            "sample_rate_hz": float(self.sample_rate_hz),
            "resolution_hz": float(self.resolution_hz),
            "line_power_fraction": float(self.line_power_fraction),
            "rms": float(self.rms),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ExcitationSummary:
        """Read back :meth:`to_dict`; raises DataError on malformed content."""
        try:
            fs = float(d["sample_rate_hz"])
            lo, hi = (float(v) for v in d["band_hz"])
            norm = d.get("band_norm")
            nlo, nhi = (float(v) for v in norm) if norm is not None else (lo / fs, hi / fs)
            return cls(
                band_hz=(lo, hi), band_norm=(nlo, nhi),
                tones_hz=tuple(float(f) for f in d.get("tones_hz", ())),
                broadband=bool(d["broadband"]), n_lines=int(d.get("n_lines", 0)),
                sample_rate_hz=fs, resolution_hz=float(d.get("resolution_hz", 0.0)),
                line_power_fraction=float(d.get("line_power_fraction", 0.0)),
                rms=float(d.get("rms", 0.0)),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"not an excitation summary: {exc!r}") from exc

    @property
    def tonal(self) -> bool:
        return not self.broadband

    def describe(self) -> str:
        lo, hi = self.band_hz
        if self.broadband:
            return f"broadband excitation, 99% of the input power in {lo:.2f}-{hi:.2f} Hz"
        tones = ", ".join(f"{f:.2f}" for f in self.tones_hz)
        return (f"tonal excitation: {self.n_lines} line(s) at {tones} Hz hold "
                f"{100 * self.line_power_fraction:.1f}% of the input power")


@dataclass(frozen=True)
class Judgement:
    """Whether a model feature at one frequency is supported by the excitation."""

    supported: bool
    note: str


def _welch(x: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
    f, p = welch(x, fs, nperseg=min(len(x), NPERSEG_MAX), detrend=False)
    p[p < FLOOR_REL * float(p.max())] = 0.0
    return f, p


def _band(f: FloatArray, p: FloatArray, res: float) -> tuple[float, float]:
    c = np.cumsum(p) / float(p.sum())
    tail = (1.0 - POWER_FRACTION) / 2.0
    lo = float(f[int(np.searchsorted(c, tail))])
    hi = float(f[min(int(np.searchsorted(c, 1.0 - tail)), len(f) - 1)])
    if lo <= 2.0 * res:
        lo = 0.0
    return lo, hi


_LOCAL = np.r_[-24:-8, 9:25]  # the neighbourhood of a line, the line's own +-8 bins left out


def _lines(p: FloatArray) -> list[int]:
    """Indices of narrow spectral lines (see the module docstring)."""
    peaks = local_maxima(np.concatenate(([0.0], p, [0.0])))
    peaks = peaks - 1
    peaks = peaks[p[peaks] > float(p.max()) * 10 ** (-LINE_DB_BELOW_MAX / 10)]
    local = np.zeros(len(peaks))
    inner = (peaks >= 24) & (peaks + 25 <= len(p))  # the whole neighbourhood inside
    if inner.any():
        local[inner] = np.median(p[peaks[inner, None] + _LOCAL], axis=1)
    for n in np.flatnonzero(~inner):
        i = int(peaks[n])
        idx = np.r_[max(i - 24, 0):max(i - 8, 0), min(i + 9, len(p)):min(i + 25, len(p))]
        local[n] = float(np.median(p[idx])) if len(idx) else 0.0
    keep = p[peaks] >= local * 10 ** (LINE_DB_OVER_LOCAL / 10)
    return [int(i) for i in peaks[keep]]


def _refine(x: FloatArray, fs: float, f0: float, res: float) -> float:
    """Peak of a zero-padded Hann periodogram of the whole record within +-res of f0."""
    nfft = int(min(max(16 * len(x), 4096), 1 << 21))
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x)), n=nfft))
    freqs = np.fft.rfftfreq(nfft, d=1.0 / fs)
    sel = np.flatnonzero(np.abs(freqs - f0) <= res)
    if len(sel) == 0:
        return f0
    return float(freqs[sel[int(np.argmax(spec[sel]))]])


def excitation_summary(
    u: Sequence[float] | NDArray[Any], sample_rate_hz: float
) -> ExcitationSummary:
    """Summarise the estimation input ``u`` sampled at ``sample_rate_hz`` (module docstring)."""
    x = np.asarray(u, dtype=np.float64).ravel()
    if not (np.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise DataError(f"sample rate must be positive and finite (got {sample_rate_hz})")
    if len(x) < 32:
        raise DataError(f"need at least 32 input samples for a spectrum (got {len(x)})")
    if not np.all(np.isfinite(x)):
        raise DataError("input has NaN/Inf samples")
    x = x - x.mean()
    if float(np.max(np.abs(x))) == 0.0:
        raise InsufficientExcitationError("input is constant: nothing is excited")
    f, p = _welch(x, sample_rate_hz)
    res = float(f[1] - f[0])
    lo, hi = _band(f, p, res)
    lines = _lines(p)
    total = float(p.sum())
    line_power = sum(
        float(p[max(i - LINE_HALF_WIDTH, 0):i + LINE_HALF_WIDTH + 1].sum()) for i in lines
    )
    frac = min(line_power / total, 1.0)
    tonal = 0 < len(lines) <= TONAL_MAX_LINES and frac >= TONAL_POWER_FRACTION
    tones = tuple(_refine(x, sample_rate_hz, float(f[i]), res) for i in lines)
    return ExcitationSummary(
        band_hz=(lo, hi), band_norm=(lo / sample_rate_hz, hi / sample_rate_hz),
        tones_hz=tones, broadband=not tonal, n_lines=len(lines),
        sample_rate_hz=float(sample_rate_hz), resolution_hz=res, line_power_fraction=frac,
        rms=float(np.sqrt(np.mean(x * x))),
    )


def tone_tolerance_hz(summary: ExcitationSummary, tone_hz: float) -> float:
    """How close a feature must be to a tone to be said to coincide with it."""
    return max(2.0 * summary.resolution_hz, TONE_REL_TOL * abs(tone_hz))


def judge(freq_hz: float, summary: ExcitationSummary | None) -> Judgement:
    """Is a model feature at ``|freq_hz|`` supported by the excitation ``summary``?"""
    if summary is None:
        return Judgement(True, "no excitation summary in the model: support not checked")
    f = abs(float(freq_hz))
    lo, hi = summary.band_hz
    tol = 2.0 * summary.resolution_hz
    if summary.tonal:
        for tone in summary.tones_hz:
            if abs(f - tone) <= tone_tolerance_hz(summary, tone):
                return Judgement(False, (
                    f"coincides with the pure-tone excitation at {tone:.2f} Hz: a sinusoid is "
                    "itself an AR(2) process, so the model can place a pole pair here "
                    "whatever the plant is"))
    if f < lo - tol or f > hi + tol:
        return Judgement(False, f"outside the excited band {lo:.2f}-{hi:.2f} Hz: extrapolated")
    if summary.tonal:
        return Judgement(False, "tonal excitation: between the tones the model is not "
                                "constrained by data")
    return Judgement(True, f"inside the excited band {lo:.2f}-{hi:.2f} Hz")


def identifiability_block(summary: ExcitationSummary | None) -> dict[str, Any]:
    """The gfrf JSON's ``identifiability`` block: what the frequency result rests on."""
    if summary is None:
        return {"excitation": None, "rests_on": (
            "unknown: the model JSON carries no 'excitation' summary, so peaks and ridges "
            "cannot be checked against the excited band")}
    return {"excitation": summary.to_dict(), "rests_on": summary.describe()}
