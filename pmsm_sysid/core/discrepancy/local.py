"""A local force over position: one Gaussian bump, its centre and width scanned.

A force that acts over a few millimetres of the stroke (a bump, a damaged magnet, a cable
snagging) is met only while the mover passes there, so its share of the residual is small
and a curve with seventeen coefficients spends most of them on noise: on held-out data it
loses what it gains. One column -- ``exp(-(x - c)²/2σ²)`` on the smoothed position, through
the parallel filter like every regressor -- is a matched filter for it. The centre is
scanned in steps of σ/2 over the 0.5-99.5 % range of the position and σ over 1/4, 1/2 and
1 knot interval of the spline (1/14 of that range): the widths the spline can draw only
with several of its coefficients; the best member is the one that explains most of the residual
beyond the model's columns, and the test is Bonferroni-corrected for the independent
members searched (the range over σ for each width). Its relevance is measured where it
acts: the share of the mismatch it explains over the samples within its half-maximum width.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray

from ..plantfit.kinematics import EquationData, thinned
from ..plantfit.library import project_made
from ..plantfit.memo import content_key

FloatArray = NDArray[np.float64]

#: Knot intervals of the curves over an axis (:mod:`.nonparam`); the bump's widths follow them.
N_INTERVALS = 14
#: Full width at half maximum of a Gaussian over its σ.
FWHM = 2.0 * math.sqrt(2.0 * math.log(2.0))

WIDTHS = tuple(f / N_INTERVALS for f in (0.25, 0.5, 1.0))  # σ as a fraction of the range
CHUNK = 16  # bump columns filtered at a time (memory)


def bump_column(x: FloatArray, centre: float, sigma: float) -> FloatArray:
    """exp(-(x - centre)² / 2σ²): a force at one place of the stroke."""
    out: FloatArray = np.exp(-0.5 * ((np.asarray(x) - centre) / sigma) ** 2)
    return out


def _bumps(x: FloatArray, members: list[tuple[float, float]]) -> FloatArray:
    out: FloatArray = np.column_stack([bump_column(x, c, s) for c, s in members])
    return out


def bump_columns(data: EquationData, members: list[tuple[float, float]]) -> FloatArray:
    """The members' columns, filtered (:meth:`.EquationData.project`), kept by the position
    and the members (:func:`.library.project_made`)."""
    what = content_key("bumps", data.x, tuple(members))
    return project_made(data, what, functools.partial(_bumps, data.x, members))


def local_grid(data: EquationData) -> tuple[list[tuple[float, float]], float]:
    """(centre, σ) members and the number of independent ones."""
    xs = thinned(data, data.x)
    lo, hi = (float(q) for q in np.quantile(xs, [0.005, 0.995]))
    travel = hi - lo
    if travel <= 0:
        return [], 1.0
    members: list[tuple[float, float]] = []
    n_ind = 0.0
    for frac in WIDTHS:
        sigma = frac * travel
        members += [(float(c), sigma) for c in np.arange(lo, hi + 1e-12, sigma / 2.0)]
        n_ind += 1.0 / frac
    return members, n_ind


def best_bump(data: EquationData, y: FloatArray,
              base: FloatArray) -> tuple[float, float] | None:
    """The member that explains most of ``y`` beyond ``base`` (least squares); the members
    are filtered ``CHUNK`` at a time, so memory does not grow with their number."""
    members, _ = local_grid(data)
    if not members:
        return None
    q = np.linalg.qr(base)[0] if base.shape[1] else np.zeros((len(y), 0))
    y = y - q @ (q.T @ y)
    gain = np.empty(len(members))
    for start in range(0, len(members), CHUNK):
        chunk = members[start:start + CHUNK]
        cols = bump_columns(data, chunk)
        cols -= q @ (q.T @ cols)
        norm = np.einsum("nk,nk->k", cols, cols)
        gain[start:start + len(chunk)] = (cols.T @ y) ** 2 / np.maximum(norm, 1e-300)
    return members[int(np.argmax(gain))]


def local_share(data: EquationData, centre: float, sigma: float, r0: FloatArray,
                r1: FloatArray) -> float:
    """Share of the mismatch explained within the half-maximum width of the bump."""
    x = thinned(data, data.x)
    inside = np.abs(x - centre) <= 0.5 * FWHM * sigma
    yy = float(data.y[inside] @ data.y[inside])
    if yy <= 0:
        return 0.0
    return float(r0[inside] @ r0[inside] - r1[inside] @ r1[inside]) / yy
