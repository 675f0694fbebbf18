"""Friction seen through a noisy speed: regression calibration with the speed's own spread.

A friction force is a function of the true speed, sharp at v = 0 (sign) and, for Stribeck
friction, over a few mm/s (the hump). The regressors can only be evaluated on the smoothed,
measured speed v̂ = v + e, e ~ N(0, σ²) with σ the measurement noise left after the
parallel filter (:func:`.kinematics.smoothed_speed_noise`). Regression calibration replaces
f(v̂) by E[f(v) | v̂]; that keeps the coefficients unbiased. Under a flat prior for v the
expectation is f convolved with the noise, which for sign(v) is a wider sign
(:func:`.averaging.sign_width`) -- but the true speed is not spread evenly: a positioning
move dwells near v = 0 at every reversal, so given v̂ = 2 mm/s the true speed is more likely
nearer zero than the flat prior says. Near zero that is exactly where the Stribeck hump
lives, and the flat-prior calibration took 30 % off its static force at 1.7 mm/s of speed
noise.

Here the prior is the distribution of the true smoothed speed, estimated from the data:
the histogram of v̂ deconvolved by the noise (Richardson-Lucy, the maximum-likelihood
deconvolution of a histogram, a fixed number of iterations as its regularisation). Then
``E[f(v) | v̂] = (k * (p f)) / (k * p)`` on a grid (k the noise kernel, p the prior, a
small flat floor where p has no mass), and the interval mean over the speed ramp of an
equation instant comes from its antiderivative, as in :func:`.averaging.interval_friction`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .memo import ContentCache, content_key, read_only

FloatArray = NDArray[np.float64]

RL_ITERATIONS = 50
POINTS_PER_WIDTH = 5  # grid points per noise width (or per quarter of the sign's width)
FLAT_FLOOR = 1e-6  # of the prior's peak: where the data have no speeds, a flat prior
CACHED_PRIORS = 16  # priors kept for the speed records seen last (SpeedPrior.from_speeds)
#: The priors themselves, by the content of the speeds, noise and base (the byte bound only
#: guards against huge grids; the count is what bounds them).
PRIORS = ContentCache(256 << 20, max_items=CACHED_PRIORS)


@dataclass(frozen=True)
class SpeedPrior:
    """The deconvolved distribution of the smoothed speed and the noise kernel on a grid."""

    grid: FloatArray
    density: FloatArray
    kernel: FloatArray

    @classmethod
    def from_speeds(cls, speeds: FloatArray, sigma: float, base: float) -> SpeedPrior:
        """Prior of the true speed behind ``speeds`` measured with noise ``sigma`` (m/s);
        ``base`` is the narrowest width a friction function has (the sign's smoothing).

        A fit builds the equation data of one recording for each plant it tries, with the
        same speeds each time: the priors of the last few speed records are kept (keyed by
        their bytes), so the deconvolution runs once per recording."""
        v = np.ascontiguousarray(speeds, dtype=np.float64)
        key = content_key("speed prior", v, float(sigma), float(base))
        return PRIORS.shared(key, lambda: cls._deconvolved(v, sigma, base),
                             lambda p: p.grid.nbytes + p.density.nbytes + p.kernel.nbytes)

    @functools.cached_property
    def _digest(self) -> bytes:
        return content_key("speed prior arrays", self.grid, self.density, self.kernel)

    def digest(self) -> bytes:
        """:func:`.memo.content_key` of the prior's arrays: hashed once when they are
        read-only (as :meth:`from_speeds` makes them), else every time. Measured: a fit
        keyed its friction columns on the prior's 0.2 MB a hundred times per recording."""
        if all(read_only(a) for a in (self.grid, self.density, self.kernel)):
            return self._digest
        return content_key("speed prior arrays", self.grid, self.density, self.kernel)

    @classmethod
    def _deconvolved(cls, v: FloatArray, sigma: float, base: float) -> SpeedPrior:
        h = max(sigma, 0.25 * base) / POINTS_PER_WIDTH
        half = math.ceil(4.0 * sigma / h)
        kernel = np.exp(-0.5 * (np.arange(-half, half + 1) * h / max(sigma, 1e-12)) ** 2)
        kernel /= kernel.sum()
        margin = 6.0 * sigma + 10.0 * base
        grid = np.arange(float(v.min()) - margin, float(v.max()) + margin + h, h,
                         dtype=np.float64)
        edges = np.append(grid - h / 2, grid[-1] + h / 2)
        hist = np.histogram(v, bins=edges)[0].astype(np.float64)
        hist /= max(float(hist.sum()), 1.0)
        p = hist + 1e-12
        for _ in range(RL_ITERATIONS if half > 0 else 0):
            blurred = np.convolve(p, kernel, mode="same")
            p = p * np.convolve(hist / np.maximum(blurred, 1e-300), kernel[::-1], mode="same")
        density = p / float(p.sum())
        for a in (grid, density, kernel):
            a.flags.writeable = False  # shared by every fit of the same speeds
        return cls(grid, density, kernel)

    def expected(self, values: FloatArray) -> FloatArray:
        """E[f(v) | v̂] on the grid, for ``values`` = f on the grid."""
        floor = FLAT_FLOOR * float(self.density.max())
        p = self.density + floor
        num = np.convolve(p * values, self.kernel, mode="same")
        den = np.convolve(p, self.kernel, mode="same")
        out: FloatArray = num / np.maximum(den, 1e-300)
        return out

    def interval_mean(self, values: FloatArray, v_lo: FloatArray,
                      v_hi: FloatArray) -> FloatArray:
        """Mean of E[f | v̂] over the speed ramp from ``v_lo`` to ``v_hi`` of each instant."""
        fc = self.expected(values)
        h = float(self.grid[1] - self.grid[0])
        anti = np.concatenate([[0.0], np.cumsum(0.5 * (fc[1:] + fc[:-1]) * h)])
        dv = v_hi - v_lo
        small = np.abs(dv) < 1e-9
        mean = (np.interp(v_hi, self.grid, anti) - np.interp(v_lo, self.grid, anti)) \
            / np.where(small, 1.0, dv)
        point = np.interp(0.5 * (v_lo + v_hi), self.grid, fc)
        out: FloatArray = np.where(small, point, mean)
        return out


def friction_values(grid: FloatArray, smoothing: float, stribeck_mps: float = 0.0,
                    ) -> FloatArray:
    """sign(v) as tanh(v / smoothing) (the simulator's convention), times the Stribeck
    hump exp(-(v/vs)²) when ``stribeck_mps`` > 0."""
    out: FloatArray = np.tanh(grid / smoothing)
    if stribeck_mps > 0:
        out = out * np.exp(-((grid / stribeck_mps) ** 2))
    return out


def calibrated_friction(prior: SpeedPrior, v_lo: FloatArray, v_hi: FloatArray,
                        smoothing: float, stribeck_mps: float = 0.0) -> FloatArray:
    """Interval mean of E[sign(v) (hump)] given the smoothed speed (module doc)."""
    return prior.interval_mean(friction_values(prior.grid, smoothing, stribeck_mps),
                               v_lo, v_hi)


