"""Peaks of H1, ridges of H2 and H3, and the poles of the linear part (Section V of Liu et al.
2005).

* **H1 peaks**: local maxima of |H1| over [0, 0.5] cycles/sample (the ends count when |H1|
  falls away from them) that stand ``min_prominence_db`` above the surrounding valleys;
  interior maxima are ``resonance``, the ends ``dc`` / ``nyquist``. Each peak carries the
  nearest pole of the linear part (its radius: 1 is the stability limit).
* **H2 ridges**, classified as the paper does: lines f1 = +-f0 or f2 = +-f0 ("energy
  release": input near f0 is amplified and mixed to other frequencies) and f1 + f2 = +-f0
  ("resonance / energy transfer": pairs of inputs summing to f0 are moved to f0). A line is
  scored by the *median* of 20 log10 |H2| along it (over the whole torus of frequencies), so a
  crossing ridge does not lift it; ridges are the local maxima of that score over f0 in
  [0, 0.5] that stand ``min_prominence_db`` (6 dB) above the median score of the family (so
  a notch nearby does not make an ordinary line a ridge), located on a 251-point scan and
  refined to 2e-4 cycles/sample; ``dominant`` marks ridges within 20 dB of the strongest
  ridge of the same order. H2_sym is symmetric, so the
  f2 ridges mirror the f1 ridges; a real model's GFRFs satisfy H(-f) = conj H(f), so every
  ridge at +f0 has its twin at -f0 (both are listed, ``sign`` = +1 / -1).
* **H3 ridges** on the paper's slice f1 = f3 (Fig. 14): lines f1 = f3 = c ("f1"; named
  "f1+f3" with f0 = 2c when 2c, not c, is an H1 peak), f2 = c ("f2"), f1 + f2 = c ("f1+f2",
  equally f2 + f3) and f1 + f2 + f3 = c ("f1+f2+f3").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..recording.spectra import find_peaks
from .gfrf import Gfrf

FloatArray = NDArray[np.float64]
LineFn = Callable[[FloatArray, FloatArray], tuple[FloatArray, ...]]
TINY = 1e-300
DOMINANT_DB = 20.0
DB_CAP = 600.0  # |H| beyond 1e30 (a pole on the unit circle) scores as 600 dB


@dataclass(frozen=True)
class Pole:
    re: float
    im: float

    @property
    def radius(self) -> float:
        return float(np.hypot(self.re, self.im))

    @property
    def freq_norm(self) -> float:
        return float(abs(np.arctan2(self.im, self.re)) / (2 * np.pi))


@dataclass(frozen=True)
class Peak:
    """A peak of |H1|."""

    kind: str               # resonance | dc | nyquist
    freq_norm: float
    freq_hz: float
    gain_db: float
    phase_deg: float
    prominence_db: float
    pole_radius: float      # radius of the linear-part pole nearest to the peak (nan if none)


@dataclass(frozen=True)
class Ridge:
    """A ridge line of H2 or H3: the line ``kind = sign * freq_norm``."""

    order: int
    kind: str
    sign: int
    freq_norm: float
    freq_hz: float
    level_db: float         # median of 20 log10 |H_n| along the line
    prominence_db: float    # level_db above the median level of all lines of its family
    dominant: bool = True   # level_db within DOMINANT_DB of the strongest ridge of its order


def poles(g: Gfrf) -> list[Pole]:
    """Poles of the linear part, largest radius first."""
    return [Pole(float(p.real), float(p.imag)) for p in g.poles()]


def _db(h: NDArray[np.complex128]) -> FloatArray:
    """20 log10 |h|, capped at +-DB_CAP (a pole on the unit circle makes |h| infinite)."""
    with np.errstate(over="ignore", invalid="ignore"):
        db = 20.0 * np.log10(np.maximum(np.abs(h), TINY))
    return np.nan_to_num(np.asarray(db, dtype=np.float64), nan=-DB_CAP, posinf=DB_CAP,
                         neginf=-DB_CAP).clip(-DB_CAP, DB_CAP)


def _mirror_peaks(y: FloatArray, min_prom: float) -> list[tuple[int, float]]:
    """Peaks of a profile on [0, 0.5] that is even about both ends (the GFRF symmetries)."""
    n = len(y)
    ext = np.concatenate((y[:0:-1], y, y[-2::-1]))
    idx, proms = find_peaks(ext, prominence=min_prom)
    out: list[tuple[int, float]] = []
    for i, prom in zip(idx, proms, strict=True):
        j = int(i) - (n - 1)
        if 0 <= j < n:
            out.append((j, float(prom)))
    return out


def _nearest_pole(pls: NDArray[np.complex128], f0: float) -> float:
    """Radius of the pole whose angle is nearest to f0 cycles/sample (nan if no poles)."""
    if len(pls) == 0:
        return float("nan")
    return float(abs(pls[np.argmin(np.abs(np.abs(np.angle(pls)) / (2 * np.pi) - f0))]))


def h1_peaks(g: Gfrf, n: int = 8193, min_prominence_db: float = 3.0) -> list[Peak]:
    """Peaks of |H1| over [0, 0.5], each refined on a 101-point local grid."""
    f, h = g.h1_curve(n)
    db = _db(h)
    if float(np.max(np.abs(h))) == 0.0:
        return []
    pls = g.poles()
    out: list[Peak] = []
    step = f[1] - f[0]
    for j, prom in _mirror_peaks(db, min_prominence_db):
        fine = np.clip(np.linspace(f[j] - step, f[j] + step, 101), 0.0, 0.5)
        hf = g.h1(fine)
        k = int(np.argmax(_db(hf)))
        f0, h0 = float(fine[k]), complex(hf[k])
        with np.errstate(divide="ignore", invalid="ignore"):
            gain = float(20 * np.log10(abs(h0))) if np.isfinite(h0) else float("inf")
        kind = "dc" if j == 0 else "nyquist" if j == n - 1 else "resonance"
        near = _nearest_pole(pls, f0)
        out.append(Peak(
            kind=kind, freq_norm=f0, freq_hz=f0 * g.sample_rate_hz,
            gain_db=gain, phase_deg=float(np.degrees(np.angle(h0))) if np.isfinite(h0) else
            float("nan"),
            prominence_db=prom, pole_radius=near,
        ))
    return sorted(out, key=lambda p: -p.gain_db)


def _line_score(g: Gfrf, line: LineFn, c: FloatArray, n_along: int) -> FloatArray:
    """Median over t of 20 log10 |H_n| along the lines parameterised by c."""
    t = (np.arange(n_along) + 0.5) / n_along - 0.5
    args = line(c[:, None], t[None, :])
    return np.asarray(np.median(_db(g.h_wrapped(*args)), axis=1), dtype=np.float64)


def _family_ridges(g: Gfrf, order: int, kind: str, line: LineFn, n_c: int, n_along: int,
                   min_excess: float) -> list[Ridge]:
    """Lines of one family whose score is a local maximum standing ``min_excess`` dB above
    the family's median score (a notch elsewhere does not make an ordinary line a ridge)."""
    c = np.linspace(0.0, 0.5, n_c)
    score = _line_score(g, line, c, n_along)
    base = float(np.median(score))
    step = c[1] - c[0]
    out: list[Ridge] = []
    for j, _ in _mirror_peaks(score, 0.5):
        if score[j] - base < min_excess:
            continue
        fine = np.clip(np.linspace(c[j] - step, c[j] + step, 21), 0.0, 0.5)
        fs = _line_score(g, line, fine, n_along)
        k = int(np.argmax(fs))
        f0, level = float(fine[k]), float(fs[k])
        for sign in (1, -1) if 0.0 < f0 < 0.5 else (1,):
            out.append(Ridge(order, kind, sign, f0, f0 * g.sample_rate_hz, level, level - base))
    return out


# Lines on the frequency torus, parameterised by c (which line) and t (where along it); the
# arrays broadcast (c is a column, t a row) and a repeated argument is the same array, so the
# evaluator shares its work (H3 on f1 = f3 needs 3 of the 6 permutations of Eq. 9).
H2_LINES: dict[str, LineFn] = {
    "f1": lambda c, t: (c, t),
    "f1+f2": lambda c, t: (t, c - t),
}
H3_LINES: dict[str, LineFn] = {
    "f1": lambda c, t: (c, t, c),
    "f2": lambda c, t: (t, c, t),
    "f1+f2": lambda c, t: (t, c - t, t),
    "f1+f2+f3": lambda c, t: (t, c - 2 * t, t),
}


def is_zero(g: Gfrf, order: int) -> bool:
    """True when H_n vanishes (checked at 64 random points: H_n is analytic in them)."""
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.5, 0.5, (order, 64))
    return float(np.max(np.abs(g.h(*pts)))) == 0.0


def h2_ridges(g: Gfrf, n_c: int = 251, n_along: int = 128,
              min_prominence_db: float = 6.0) -> list[Ridge]:
    """Ridges of |H2_sym| (module docstring); [] when H2 is identically zero."""
    if is_zero(g, 2):
        return []
    f1 = _family_ridges(g, 2, "f1", H2_LINES["f1"], n_c, n_along, min_prominence_db)
    f2 = [replace(r, kind="f2") for r in f1]
    fs = _family_ridges(g, 2, "f1+f2", H2_LINES["f1+f2"], n_c, n_along, min_prominence_db)
    return _sorted(f1 + f2 + fs)


def h3_ridges(g: Gfrf, n_c: int = 251, n_along: int = 96, min_prominence_db: float = 6.0,
              h1_peak_norm: tuple[float, ...] = ()) -> list[Ridge]:
    """Ridges of |H3_sym| on the slice f1 = f3 (module docstring); [] when H3 is zero."""
    if is_zero(g, 3):
        return []
    out: list[Ridge] = []
    tol = 2.0 / (n_c - 1)
    for kind, line in H3_LINES.items():
        for r in _family_ridges(g, 3, kind, line, n_c, n_along, min_prominence_db):
            if kind == "f1" and h1_peak_norm:
                d1 = min(abs(r.freq_norm - p) for p in h1_peak_norm)
                d2 = min(abs(2 * r.freq_norm - p) for p in h1_peak_norm)
                if d2 < d1 and d2 <= tol:
                    r = replace(r, kind="f1+f3", freq_norm=2 * r.freq_norm,
                                freq_hz=2 * r.freq_hz)
            out.append(r)
    return _sorted(out)


def _sorted(rs: list[Ridge]) -> list[Ridge]:
    top = max((r.level_db for r in rs), default=0.0)
    rs = [replace(r, dominant=r.level_db >= top - DOMINANT_DB) for r in rs]
    return sorted(rs, key=lambda r: (-r.level_db, r.kind, -r.sign))
