"""Where a force residual lives: over time, position, velocity and frequency.

Each axis gets a generic, physics-free basis -- 16 equal time windows, 16 position bins,
16 velocity bins (quantiles), and a sin/cos pair at the strongest spectral line -- and the
basis is put to the same prewhitened nested F-test as the library effects (:mod:`.stats`),
against whatever model is already fitted. ``share`` is the fraction of the residual energy
the basis explains on its own; the axes overlap, so ``added_share`` (in the details) is what
each adds beyond the axes that explain more on their own: those add up to at most 1. Run
on the nominal residual this says where the mismatch is; run on the residual of the final
model it finds what no library effect explained (``unexplained``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..plantfit.kinematics import EquationData, thinned, thinned_sizes, thinned_times
from ..plantfit.stats import f_logsf, lstsq, nested_f_test

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


NEIGHBOURS = 8  # bins each side that set the local noise level of a spectral line
#: A line's frequency is refined over ±1 bin, so each bin searched stands for three: the
#: Bonferroni count of the line test (on white and coloured noise the refined peak over
#: its local level exceeds the F(2, 28) tail about twice as often as one bin does).
REFINED = 3


def _ratio(spec: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each bin's power over the mean of its 2*NEIGHBOURS neighbours (its own ±1 left out)."""
    n = len(spec)
    kern = np.ones(2 * NEIGHBOURS + 1)
    kern[NEIGHBOURS - 1:NEIGHBOURS + 2] = 0.0
    total = np.convolve(spec, kern, mode="same")
    count = np.convolve(np.ones(n), kern, mode="same")
    level = total / np.maximum(count, 1.0)
    return spec / np.maximum(level, 1e-300), level


def _line_at(rc: FloatArray, tt: FloatArray, f: float) -> float:
    """Periodogram value |sum r exp(-2 pi i f t)|^2 at any frequency."""
    z = rc @ np.exp(-2j * math.pi * f * tt)
    return float(abs(z) ** 2)


def strongest_line(r: FloatArray, t: FloatArray, fs: float, u: FloatArray | None = None,
                   sizes: tuple[int, ...] = ()) -> tuple[float, float, float, int, float]:
    """The residual's most prominent spectral line, judged against its neighbours.

    A line is a bin whose power stands out of the residual's own spectrum around it (the
    local level of the 2x8 neighbouring bins): coloured noise has no such bins, so the
    test holds whatever the noise's colour. Bins where the input ``u`` itself has a line
    (periodic excitations: multisine, PRBS periods and holds) are left out -- a line the
    input puts there is the input's, not the plant's. The frequency is refined by least
    squares over ±1 bin (the periodogram peak is good to half a bin only).

    ``sizes``: the lengths of the contiguous parts ``r`` is made of (spans of a long
    recording); the periodogram is then each part's, averaged (every part cut to the
    shortest): a line keeps its phase within a part, not across a gap, and the average of
    K periodograms has 2K degrees of freedom per bin (:func:`line_dof`).

    Returns (frequency Hz, power share of the refined line, ratio to the local level,
    number of bins searched, share of the power of the bins around it).
    """
    pieces = _pieces(r, t, sizes)
    n = min(len(p[0]) for p in pieces)
    rcs = [(p[0][:n] - p[0][:n].mean(), p[1][:n] - p[1][0]) for p in pieces]
    spec = np.mean([np.abs(np.fft.rfft(rc)) ** 2 for rc, _ in rcs], axis=0)
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    ratio, level = _ratio(spec)
    ok = np.zeros(len(spec), dtype=bool)
    ok[2:len(spec) - 1] = True
    if u is not None:
        ups = [p[0][:n] for p in _pieces(u, t, sizes)]
        uspec = np.mean([np.abs(np.fft.rfft(x - x.mean())) ** 2 for x in ups], axis=0)
        uratio, _ = _ratio(uspec)
        ok &= uratio < math.log(len(spec) / 1e-3)  # no significant input line at that bin
    if not ok.any():
        return 0.0, 0.0, 0.0, 1, 0.0
    k = int(np.flatnonzero(ok)[np.argmax(ratio[ok])])
    bin_hz = fs / n
    best = (float(spec[k]), float(freqs[k]))
    for f in np.linspace(freqs[k] - bin_hz, freqs[k] + bin_hz, 41):
        if f > 0:
            power = float(np.mean([_line_at(rc, tt, float(f)) for rc, tt in rcs]))
            best = max(best, (power, float(f)))
    energy = float(np.mean([rc @ rc for rc, _ in rcs]))
    share = 2.0 * best[0] / n / max(energy, 1e-300)
    band = float(spec[max(k - NEIGHBOURS, 0):k + NEIGHBOURS + 1].sum())
    return (best[1], min(share, 1.0), best[0] / max(float(level[k]), 1e-300), int(ok.sum()),
            min(best[0] / max(band, 1e-300), 1.0))


def _pieces(r: FloatArray, t: FloatArray,
            sizes: tuple[int, ...]) -> list[tuple[FloatArray, FloatArray]]:
    edges = np.cumsum([0, *(sizes or (len(r),))])
    return [(r[a:b], t[a:b]) for a, b in itertools.pairwise(edges)]


def line_dof(parts: int) -> tuple[int, int]:
    """Degrees of freedom of a bin of the averaged periodogram over its local level."""
    return 2 * parts, (4 * NEIGHBOURS - 4) * parts


def _sincos(t: FloatArray, f: float) -> FloatArray:
    return np.column_stack([np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)])


def scan_axes(data: EquationData, y: FloatArray, base: FloatArray,
              n_bins: int = N_BINS, total: float | None = None,
              null_whitening: bool = False, thrust: bool = False,
              extra: dict[str, tuple[FloatArray, float]] | None = None) -> list[AxisFinding]:
    """Axis findings for residual target ``y`` beyond the columns ``base`` (module doc).

    Shares are fractions of ``total`` (default: the energy of ``y``). ``null_whitening``
    (see :func:`.stats.nested_f_test`) keeps the bin tests at their level when ``y`` beyond
    ``base`` is noise, as it is when looking for what the final model left unexplained;
    describing a raw mismatch, where ``y`` is mostly the effect, it would whiten the effect
    away. ``extra``: axis -> (columns, share alone) that describe an axis beside its bins
    (the best cogging period over position), counted in its ``added_share``.
    """
    t = thinned_times(data)
    x = thinned(data, data.x)
    v = thinned(data, data.v_axis)
    _, r = lstsq(base, y)
    yy = float(y @ y) if total is None else total
    out = []
    bases = {"time": _bins(t, n_bins, False)[0], "position": _bins(x, n_bins, True)[0],
             "velocity": _bins(v, n_bins, True)[0]}
    if thrust:  # open loop only: under feedback the thrust carries the sensor noise
        bases["thrust"] = _bins(thinned(data, data.thrust_axis), n_bins, True)[0]
    n_freq = len(r) // 2
    for axis, ind in bases.items():
        test = nested_f_test(y, base, ind, null_whitening=null_whitening)
        _, r1 = lstsq(np.hstack([base, ind]), y)
        share = float(r @ r - r1 @ r1) / yy
        details: dict[str, Any] = {}
        if axis == "time":
            details = _time_details(r, t, ind)
        elif axis in ("position", "thrust"):
            vals = x if axis == "position" else thinned(data, data.thrust_axis)
            details = {"bin_means_n": _bin_means(r, ind).tolist(),
                       f"{axis}_range": [float(vals.min()), float(vals.max())]}
        else:
            details = _velocity_details(r, v)
        out.append(AxisFinding(axis, share, -test.corrected_log10_p(len(bases) + 1), details))
    u = data.project(data.force)
    sizes = thinned_sizes(data)
    f0, line_share, ratio, n_freq, local = strongest_line(r, t, data.sample_rate_hz, u,
                                                         sizes)
    cols = _sincos(t - t[0], f0)
    _, r1 = lstsq(np.hstack([base, cols]), y)
    dof1, dof2 = line_dof(max(1, len(sizes)))
    logp = f_logsf(ratio, dof1, dof2) / math.log(10.0) if f0 > 0 else 0.0
    sig = max(0.0, -(logp + math.log10(len(bases) + REFINED * n_freq)))
    out.append(AxisFinding("frequency", float(r @ r - r1 @ r1) / yy, sig,
                           {"line_hz": f0, "line_power_share": line_share,
                            "line_to_local_level": ratio, "line_local_share": local}))
    every = {**bases, "frequency": cols}
    alone = {f.axis: f.share for f in out}
    for axis, (more, share) in (extra or {}).items():
        every[axis] = np.hstack([every[axis], more])
        alone[axis] = max(alone[axis], share)
    added = added_shares(y, base, every, alone, yy)
    return [AxisFinding(f.axis, f.share, f.significance,
                        {**f.details, "added_share": added[f.axis]}) for f in out]


def added_shares(y: FloatArray, base: FloatArray, bases: dict[str, FloatArray],
                 alone: dict[str, float], total: float) -> dict[str, float]:
    """What each axis explains beyond the axes that explain more on their own (taken in that
    order, as ERR takes terms): the axes overlap (a force over speed shows over time too),
    so their ``share`` alone does not add up; these do, to at most the whole residual."""
    cols = base
    _, r = lstsq(cols, y)
    before = float(r @ r)
    out = {}
    for axis in sorted(bases, key=lambda a: -alone[a]):
        cols = np.hstack([cols, bases[axis]])
        _, r = lstsq(cols, y)
        now = float(r @ r)
        out[axis] = max(before - now, 0.0) / total
        before = now
    return out
