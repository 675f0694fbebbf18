"""Thrust excitation signals, seeded and deterministic.

Every signal is a pure function of the sample index ``k`` (and the random seed), so any block of it
can be produced on its own: ``block(0, 10) == concat(block(0, 4), block(4, 6))``. The random
signals (multisine, PRBS, APRBS) and the chirp are periodic with a documented period.

``amplitude_n`` is the peak thrust |F| (N). For the two paper signals it is the amplitude of
the main tone. Defaults suit the 83 W, 1 m/s motor of the paper's Table 1 (B = 32.5 N/(m/s)):

* ``paper-speed``: sine at 16.5 Hz (0.033 cycles/sample at 500 Hz, Fig. 3 of Liu et al. (2005)), 50
N, giving
  speeds of about +-20 cm/s (Fig. 2 of Liu et al. 2005).
* ``paper-position``: sine at 11.5 Hz (0.023 cycles/sample, Fig. 8 of Liu et al. (2005)), 40 N,
plus a slow
  positioning move (cosine at 0.5 Hz, 3 N) that gives the cm-scale travel of Fig. 7 of Liu et al.
  (2005) and the output energy near 0 Hz the paper reports.
* ``broadband`` (the default of ``pmsm-sysid run``): the multisine below on every 0.25 Hz
  line from 0.5 Hz to 240 Hz (0.96 x Nyquist at 500 Hz; lines at or above Nyquist are
  dropped), random phases, 60 N peak (about 19 N rms, speeds of about +-7 cm/s rms). Its
  spectrum is flat over almost the whole band, so it is persistently exciting of order 40 and
  more over 40 input lags, and its amplitude takes many values, so products of lagged inputs
  (degree-2 NARX terms) are distinguishable from the linear ones.
* ``multisine``: flat amplitude spectrum on every FFT line of one period within
  [f_min_hz, f_max_hz], random (seeded) or Schroeder phases, scaled to the peak.
* ``chirp``: swept sine f0_hz -> f1_hz over period_s (linear or logarithmic), repeated.
* ``prbs``: maximum-length binary sequence of ``order`` bits, each held ``hold`` samples.
* ``aprbs``: amplitude-modulated PRBS: uniform random levels in [-A, A] held for random
  durations in [min_hold, max_hold] samples.

The paper signals start with a raised-cosine fade-in (``fade_s``, 0.5 s) so that the
mass-damper does not carry a start-up transient into the speed or position.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import ExcitationError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

EXCITATIONS = ("paper-speed", "paper-position", "multisine", "chirp", "prbs", "aprbs",
               "broadband")

DEFAULT_AMPLITUDE_N: dict[str, float] = {
    "paper-speed": 50.0, "paper-position": 40.0, "multisine": 30.0,
    "chirp": 30.0, "prbs": 20.0, "aprbs": 20.0, "broadband": 60.0,
}

DEFAULT_OPTIONS: dict[str, dict[str, Any]] = {
    "paper-speed": {"frequency_hz": 16.5, "fade_s": 0.5},
    "paper-position": {"frequency_hz": 11.5, "slow_hz": 0.5, "slow_amplitude_n": 3.0,
                       "fade_s": 0.5},
    "multisine": {"f_min_hz": 1.0, "f_max_hz": 40.0, "period_s": 4.0, "phases": "random"},
    "chirp": {"f0_hz": 2.0, "f1_hz": 50.0, "period_s": 10.0, "method": "linear"},
    "prbs": {"order": 10, "hold": 5},
    "aprbs": {"min_hold": 10, "max_hold": 100, "period_s": 20.0},
    "broadband": {"f_min_hz": 0.5, "f_max_hz": 240.0, "period_s": 4.0, "phases": "random"},
}

_CHOICES: dict[str, tuple[str, ...]] = {
    "phases": ("random", "schroeder"), "method": ("linear", "logarithmic"),
}


def _options(kind: str, given: Mapping[str, Any]) -> dict[str, Any]:
    defaults = DEFAULT_OPTIONS[kind]
    unknown = sorted(set(given) - set(defaults))
    if unknown:
        raise ExcitationError(f"{kind}: unknown option(s) {', '.join(unknown)}; valid: "
                              f"{', '.join(defaults)}")
    opts = {**defaults, **given}
    for name, value in opts.items():
        if name in _CHOICES:
            if value not in _CHOICES[name]:
                raise ExcitationError(f"{kind}: {name} must be one of "
                                      f"{', '.join(_CHOICES[name])}, got {value!r}")
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise ExcitationError(f"{kind}: {name} must be a finite number, got {value!r}")
        if value < 0 or (value == 0 and name not in ("fade_s", "slow_amplitude_n", "slow_hz")):
            raise ExcitationError(f"{kind}: {name} must be positive, got {value}")
    return opts


def _periodic(one_period: FloatArray) -> Callable[[IntArray], FloatArray]:
    def fn(k: IntArray) -> FloatArray:
        return one_period[k % len(one_period)]
    return fn


def _fade(k: IntArray, fs: float, fade_s: float) -> FloatArray:
    if fade_s <= 0:
        return np.ones(len(k))
    t = k / fs
    return np.where(t < fade_s, 0.5 * (1.0 - np.cos(np.pi * t / fade_s)), 1.0)


def _paper(fs: float, amp: float, o: dict[str, Any]) -> Callable[[IntArray], FloatArray]:
    def fn(k: IntArray) -> FloatArray:
        t = k / fs
        main = amp * np.sin(2.0 * np.pi * o["frequency_hz"] * t)
        slow = o.get("slow_amplitude_n", 0.0) * np.cos(2.0 * np.pi * o.get("slow_hz", 0.0) * t)
        out: FloatArray = _fade(k, fs, o["fade_s"]) * (main + slow)
        return out
    return fn


def _period_samples(kind: str, fs: float, period_s: float) -> int:
    n = round(period_s * fs)
    if n < 4:
        raise ExcitationError(f"{kind}: period_s={period_s} is shorter than 4 samples")
    return n


def _multisine(fs: float, amp: float, o: dict[str, Any],
               rng: np.random.Generator) -> Callable[[IntArray], FloatArray]:
    n = _period_samples("multisine", fs, o["period_s"])
    df = fs / n
    lines = np.arange(1, n // 2 + 1)
    lines = lines[(lines * df >= o["f_min_hz"] - 1e-9) & (lines * df <= o["f_max_hz"] + 1e-9)]
    lines = lines[lines < n / 2]  # keep clear of Nyquist
    if len(lines) == 0:
        raise ExcitationError(f"multisine: no frequency line in [{o['f_min_hz']}, "
                              f"{o['f_max_hz']}] Hz at {df:.4g} Hz resolution (period_s "
                              f"{o['period_s']}, {fs} Hz)")
    j = np.arange(1, len(lines) + 1)
    if o["phases"] == "schroeder":
        phases = -np.pi * j * (j - 1) / len(lines)
    else:
        phases = rng.uniform(0.0, 2.0 * np.pi, len(lines))
    spectrum = np.zeros(n // 2 + 1, dtype=np.complex128)
    spectrum[lines] = np.exp(1j * phases)
    one = np.fft.irfft(spectrum, n)
    return _periodic(amp * one / np.max(np.abs(one)))


def _chirp(fs: float, amp: float, o: dict[str, Any]) -> Callable[[IntArray], FloatArray]:
    f0, f1, period = float(o["f0_hz"]), float(o["f1_hz"]), float(o["period_s"])
    n = _period_samples("chirp", fs, period)
    if max(f0, f1) >= fs / 2:
        raise ExcitationError(f"chirp: frequencies must stay below Nyquist ({fs / 2} Hz)")
    t = np.arange(n) / fs
    if o["method"] == "linear":
        phase = f0 * t + 0.5 * (f1 - f0) / period * t * t
    else:
        if f0 == f1:
            phase = f0 * t
        else:
            beta = period / math.log(f1 / f0)
            phase = f0 * beta * (np.power(f1 / f0, t / period) - 1.0)
    return _periodic(amp * np.cos(2.0 * np.pi * phase))


def _prbs(amp: float, o: dict[str, Any],
          rng: np.random.Generator) -> Callable[[IntArray], FloatArray]:
    from scipy.signal import max_len_seq

    order, hold = o["order"], o["hold"]
    if int(order) != order or not 2 <= order <= 18 or int(hold) != hold:
        raise ExcitationError(f"prbs: order must be an integer in 2..18 and hold an integer "
                              f"(got order={order}, hold={hold})")
    state = rng.integers(0, 2, int(order))
    if not state.any():
        state[0] = 1
    bits = max_len_seq(int(order), state=state)[0]
    return _periodic(np.repeat(amp * (2.0 * bits - 1.0), int(hold)))


def _aprbs(fs: float, amp: float, o: dict[str, Any],
           rng: np.random.Generator) -> Callable[[IntArray], FloatArray]:
    lo, hi = o["min_hold"], o["max_hold"]
    if int(lo) != lo or int(hi) != hi or hi < lo:
        raise ExcitationError(f"aprbs: min_hold and max_hold must be integers with "
                              f"min_hold <= max_hold (got {lo}, {hi})")
    n = _period_samples("aprbs", fs, o["period_s"])
    one = np.empty(n)
    k = 0
    while k < n:
        length = int(rng.integers(int(lo), int(hi) + 1))
        one[k:k + length] = rng.uniform(-amp, amp)
        k += length
    return _periodic(one)


class ExcitationSource:
    """A thrust signal of the given kind, evaluated block by block (see module doc)."""

    def __init__(self, kind: str, sample_rate_hz: float, seed: int = 0,
                 amplitude_n: float | None = None, **options: Any) -> None:
        if kind not in EXCITATIONS:
            raise ExcitationError(f"unknown excitation '{kind}'; valid: {', '.join(EXCITATIONS)}")
        if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
            raise ExcitationError(f"sample rate must be positive, got {sample_rate_hz}")
        amp = DEFAULT_AMPLITUDE_N[kind] if amplitude_n is None else amplitude_n
        if isinstance(amp, bool) or not isinstance(amp, (int, float)) \
                or not (math.isfinite(amp) and amp >= 0):
            raise ExcitationError(f"{kind}: amplitude must be a finite number >= 0, got {amp!r}")
        self.kind = kind
        self.sample_rate_hz = float(sample_rate_hz)
        self.seed = int(seed)
        self.amplitude_n = float(amp)
        self.options = _options(kind, options)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, EXCITATIONS.index(kind)]))
        self._fn = self._build(rng)

    def _build(self, rng: np.random.Generator) -> Callable[[IntArray], FloatArray]:
        fs, amp, o = self.sample_rate_hz, self.amplitude_n, self.options
        if self.kind.startswith("paper-"):
            if o["frequency_hz"] >= fs / 2:
                raise ExcitationError(f"{self.kind}: frequency_hz must be below Nyquist "
                                      f"({fs / 2} Hz)")
            return _paper(fs, amp, o)
        if self.kind in ("multisine", "broadband"):
            return _multisine(fs, amp, o, rng)
        if self.kind == "chirp":
            return _chirp(fs, amp, o)
        if self.kind == "prbs":
            return _prbs(amp, o, rng)
        return _aprbs(fs, amp, o, rng)

    def block(self, k0: int, n: int) -> FloatArray:
        """Samples ``k0 .. k0+n-1`` of the signal (N)."""
        if k0 < 0 or n < 0:
            raise ExcitationError(f"block needs k0 >= 0 and n >= 0, got k0={k0}, n={n}")
        k = np.arange(k0, k0 + n, dtype=np.int64)
        return np.asarray(self._fn(k), dtype=np.float64)

    def value(self, k: int) -> float:
        """Sample ``k`` (N); the live sim node asks one sample at a time."""
        return float(self.block(k, 1)[0])


def make_excitation(kind: str, n_samples: int, sample_rate_hz: float, seed: int = 0,
                    amplitude_n: float | None = None, **options: Any) -> FloatArray:
    """``n_samples`` of the excitation from k = 0 (= ``ExcitationSource(...).block(0, n)``)."""
    src = ExcitationSource(kind, sample_rate_hz, seed=seed, amplitude_n=amplitude_n, **options)
    return src.block(0, n_samples)
