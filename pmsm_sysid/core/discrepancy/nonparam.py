"""A model for what no library effect explains: a smooth curve of the residual force.

When the final model's residual is still structured on an axis, the force it leaves out is
modelled without naming it, as a cubic B-spline of the axis variable (position, velocity or
the thrust command), or over position times sign(v) (a friction that depends on where the
mover is), or as one Gaussian bump over position (a local force: one column, its centre
and width scanned by :mod:`.local`, so that a small force at one place of the stroke is
not lost in the noise of seventeen coefficients), or -- over time -- as one slow sinusoid
at the residual's strongest line (a periodic disturbance; a spline over time would not
carry over to other data). The curve's
columns go through the same parallel filter as every regressor and are fitted with the
library model's columns; it is then judged like an effect: on held-out data, with its
estimation coefficients. Where it lives is read off the curve: the region around its
largest excursion from its median level (position, velocity) or where its slope departs
most from its typical slope (thrust: a dead zone or a saturation is a turn of the curve).

Under feedback the curve over thrust is fitted with a straight line over thrust beside it
(``line``) and judged against that line alone: the loop makes the thrust answer the sensor
noise and the process force, which are in the residual too, so the residual leans on the
thrust in a straight line whatever the plant (errors in variables); only a bend in the
curve -- a dead zone, a saturation -- is the plant's.

Open loop a noisy thrust *reading* bends that lean too: the noise ``n`` is in the residual
and in the recorded thrust ``u = f + n``, and its mean given the reading is
``E[n | u] = -s² d/du log p(u)`` (Tweedie's formula; ``p`` the density of the readings,
``s`` the noise's deviation) -- a straight line for a Gaussian thrust, but steep at the
ends of a bounded one (a chirp's or a sine's crests), where a reading beyond the range
can only be noise. With ``lean`` that column (``p`` a kernel estimate of the readings'
density, its coefficient free, so ``s`` need not be known) is fitted beside the line and
the curve is judged against both: only a bend the readings' own distribution does not
explain -- a dead zone in the middle of the range -- is the plant's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from ..plantfit.kinematics import EquationData, thinned, thinned_times
from ..plantfit.library import project_made
from ..plantfit.memo import content_key
from ..plantfit.stats import ar_whitener, lstsq, whiten
from .local import FWHM, N_INTERVALS, best_bump, bump_column

FloatArray = NDArray[np.float64]

DEGREE = 3
#: Kernel width of the readings' density for the noise lean, as a share of their
#: interquartile range (fine enough for a noise of a few percent of the range).
LEAN_BANDWIDTH = 0.03
#: Grid steps per kernel width of the binned density estimate.
LEAN_STEPS = 4
UNITS = {"position": "m", "velocity": "m/s", "thrust": "N", "time": "s",
         "position_friction": "m", "position_local": "m"}


@dataclass(frozen=True)
class AxisModel:
    """A fitted curve over one axis: knots range, coefficients and their covariance."""

    axis: str
    lo: float
    hi: float
    coef: FloatArray
    cov: FloatArray
    freq_hz: float = 0.0
    line: float | None = None  # a straight line over thrust fitted with the curve ...
    line0: float = 0.0  # ... and fitted alone
    inner: tuple[float, float] | None = None  # 5-95 % of the axis values (thrust turns)
    bump: tuple[float, float] = (0.0, 0.0)  # position_local: centre and σ (m)
    lean: float | None = None  # the thrust reading's noise lean fitted with the curve ...
    lean0: float = 0.0  # ... and with the line alone

    def _beside(self, data: EquationData, line: float | None, lean: float) -> FloatArray:
        """The line and noise lean (coefficients given) at the regression samples."""
        out: FloatArray = np.zeros(data.n)
        if line is not None:
            out = out + line * data.project(data.thrust_axis)
        if self.lean is not None:
            out = out + lean * data.project(noise_lean(data.force))
        return out

    def raw(self, data: EquationData) -> FloatArray:
        """Full-rate columns on ``data`` (values clipped to the fitted range)."""
        if self.axis == "time":
            tt = 2.0 * math.pi * self.freq_hz * data.t
            return np.column_stack([np.sin(tt), np.cos(tt)])
        if self.axis == "position_local":
            return bump_column(data.x, *self.bump)[:, None]
        vals = axis_values(data, self.axis)
        basis = _basis(np.clip(vals, self.lo, self.hi), self.lo, self.hi)
        if self.axis == "position_friction":
            s = data.friction()
            basis = basis * s[:, None]
        return basis

    def projected(self, data: EquationData) -> FloatArray:
        """``data.project(self.raw(data))``, kept by what the columns are made of (the
        axis's values, the curve's range; :func:`.library.project_made`): a diagnosis
        projects the same curve's columns many times, and building them and hashing 17
        full-rate columns for each lookup cost more than hashing the axis."""
        if self.axis == "time":
            inputs: tuple[object, ...] = (data.t,)
        elif self.axis == "position_friction":
            inputs = (data.x, data.friction())
        elif self.axis == "position_local":
            inputs = (data.x,)
        else:
            inputs = (axis_values(data, self.axis),)
        what = content_key("axis model", self.axis, self.lo, self.hi, self.freq_hz,
                           self.bump, *inputs)
        return project_made(data, what, lambda: self.raw(data))

    def force(self, data: EquationData) -> FloatArray:
        """The modelled force at the regression samples of ``data`` (with the line)."""
        out: FloatArray = self.projected(data) @ self.coef
        return out + self._beside(data, self.line, self.lean or 0.0)

    def baseline(self, data: EquationData) -> FloatArray:
        """The force of the line (and noise lean) fitted alone (zero without one): the
        curve's rival."""
        return self._beside(data, None if self.line is None else self.line0, self.lean0)

    def _describe_bump(self) -> dict[str, Any]:
        c, sig = self.bump
        amp = float(self.coef[0])
        at = np.linspace(c - 3 * sig, c + 3 * sig, 15)
        half = 0.5 * FWHM * sig
        return {"model": "Gaussian bump over position (a local force)",
                "region": [c - half, c + half], "peak_at": c, "peak_n": amp,
                "width": 2 * half, "sigma_m": sig, "unit": "m",
                "curve": {"at": at.tolist(), "force_n": (amp * bump_column(at, c, sig)).tolist()}}

    def describe(self) -> dict[str, Any]:
        """Where the curve lives: region, peak and a coarse table of the curve."""
        if self.axis == "time":
            amp = float(np.hypot(*self.coef))
            return {"model": "sinusoid over time", "frequency_hz": self.freq_hz,
                    "amplitude_n": amp, "period_s": 1.0 / max(self.freq_hz, 1e-12), "unit": "s"}
        if self.axis == "position_local":
            return self._describe_bump()
        grid = np.linspace(self.lo, self.hi, 201)
        g = _basis(grid, self.lo, self.hi) @ self.coef + (self.line or 0.0) * grid
        rel = g - float(np.median(g))
        if self.axis == "thrust":
            score = _rise(grid, g, self.inner or (self.lo, self.hi))
        else:
            score = np.abs(rel)
        k = int(np.argmax(score))
        inside = score >= 0.5 * score[k]
        a = b = k
        while a > 0 and inside[a - 1]:
            a -= 1
        while b < len(grid) - 1 and inside[b + 1]:
            b += 1
        kind = ", friction (force x sign of speed)" if self.axis == "position_friction" \
            else ""
        pick = np.linspace(0, len(grid) - 1, 15).astype(int)
        return {"model": f"cubic B-spline over {self.axis.split('_')[0]}{kind}",
                "region": [float(grid[a]), float(grid[b])], "peak_at": float(grid[k]),
                "peak_n": float(rel[k]), "width": float(grid[b] - grid[a]),
                "unit": UNITS[self.axis],
                "curve": {"at": grid[pick].tolist(), "force_n": g[pick].tolist()}}


def _rise(grid: FloatArray, g: FloatArray, inner: tuple[float, float]) -> FloatArray:
    """How much steeper than its typical slope the curve rises (a dead zone's turn), over
    the knot spacing (the spline's own resolution) and among the values often met."""
    h = (grid[-1] - grid[0]) / N_INTERVALS
    slope = (np.interp(grid + h / 2, grid, g) - np.interp(grid - h / 2, grid, g)) / h
    core = (grid >= inner[0]) & (grid <= inner[1])
    if not core.any():
        core = np.ones(len(grid), dtype=bool)
    out: FloatArray = np.where(core, np.maximum(slope - float(np.median(slope[core])), 0.0),
                               0.0)
    return out


def axis_values(data: EquationData, axis: str) -> FloatArray:
    """Full-rate values of an axis at the equation instants."""
    if axis in ("position", "position_friction"):
        return data.x
    if axis == "velocity":
        return data.v_axis
    if axis == "thrust":
        return data.thrust_axis
    out: FloatArray = data.t
    return out


def noise_lean(vals: FloatArray) -> FloatArray:
    """``-d/du log p(u)`` at each of ``vals``, ``p`` their own density (a Gaussian kernel
    of ``LEAN_BANDWIDTH`` of their interquartile range, binned): the shape of a reading
    noise's mean given the reading (module doc)."""
    from scipy.ndimage import gaussian_filter1d

    u = np.asarray(vals, dtype=np.float64)
    q25, q75 = np.quantile(u, [0.25, 0.75])
    h = LEAN_BANDWIDTH * float(q75 - q25) or 1e-9 * max(1.0, float(np.max(np.abs(u))))
    step = h / LEAN_STEPS
    lo = float(u.min()) - 4 * h
    nbins = int(np.ceil((float(u.max()) + 4 * h - lo) / step)) + 1
    counts = np.bincount(np.clip(((u - lo) / step).astype(int), 0, nbins - 1),
                         minlength=nbins).astype(np.float64)
    dens = gaussian_filter1d(counts, LEAN_STEPS, mode="constant")
    score = -np.gradient(np.log(np.maximum(dens, 1e-300)), step)
    out: FloatArray = np.interp(u, lo + step * np.arange(nbins), score)
    return out


def _basis(vals: FloatArray, lo: float, hi: float) -> FloatArray:
    inner = np.linspace(lo, hi, N_INTERVALS + 1)
    knots = np.concatenate([[lo] * DEGREE, inner, [hi] * DEGREE])
    v = np.clip(np.asarray(vals, dtype=np.float64), lo, hi)
    out: FloatArray = BSpline.design_matrix(v, knots, DEGREE).toarray()
    return out


def _slow_line(r: FloatArray, t: FloatArray) -> float:
    """Frequency of the strongest slow line (from one cycle over the data), least squares."""
    span = float(t[-1] - t[0])
    best = (0.0, 1.0 / span)
    for f in np.linspace(0.5 / span, 10.0 / span, 77):
        cols = np.column_stack([np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)])
        _, e = lstsq(cols, r)
        best = max(best, (float(r @ r - e @ e), float(f)))
    return best[1]


def fit_axis(data: EquationData, y: FloatArray, base: FloatArray, axis: str,
             line: bool = False, lean: bool = False) -> AxisModel:
    """Fit the curve of ``axis`` to ``y`` together with the columns ``base``."""
    return fit_axis_with(data, y, base, axis, line, lean=lean)[0]


def beside_thrust(data: EquationData, lean: bool) -> FloatArray:
    """The columns fitted beside a curve over thrust: the line, and the noise lean."""
    cols = [data.project(data.thrust_axis)] + ([data.project(noise_lean(data.force))] if lean
                                         else [])
    return np.column_stack(cols)


def fit_axis_with(data: EquationData, y: FloatArray, base: FloatArray, axis: str,
                  line: bool = False, freq_hz: float = 0.0, lean: bool = False,
                  ) -> tuple[AxisModel, FloatArray, float]:
    """The curve, the coefficients of ``base`` fitted with it, and the residual energy.

    ``line`` (thrust only): a straight line over thrust is fitted beside the curve and
    kept in the model (module doc); its coefficient without the curve is kept too.
    ``lean`` (with ``line``): so is the thrust reading's noise lean (module doc).
    ``freq_hz`` (time only): the sinusoid's frequency when known (a spectral line), else
    the strongest slow line.
    """
    m = base.shape[1]
    line0 = None
    lean0 = None
    if line and axis == "thrust":
        base = np.hstack([base, beside_thrust(data, lean)])
        b0 = lstsq(base, y)[0]
        line0 = float(b0[m])
        lean0 = float(b0[m + 1]) if lean else None
    if axis == "time":
        _, r = lstsq(base, y)
        freq = freq_hz if freq_hz > 0 else _slow_line(r, thinned_times(data))
        model = AxisModel(axis, 0.0, 0.0, np.zeros(2), np.eye(2), freq)
    elif axis == "position_local":
        c, sig = best_bump(data, y, base) or (0.0, 1.0)
        model = AxisModel(axis, c - 3 * sig, c + 3 * sig, np.zeros(1), np.eye(1),
                          bump=(c, sig))
    else:
        vals = thinned(data, axis_values(data, axis))
        lo, hi = float(np.quantile(vals, 0.005)), float(np.quantile(vals, 0.995))
        if hi <= lo:
            hi = lo + 1e-9
        q5, q95 = (float(q) for q in np.quantile(vals, [0.05, 0.95]))
        model = AxisModel(axis, lo, hi, np.zeros(N_INTERVALS + DEGREE),
                          np.eye(N_INTERVALS + DEGREE), inner=(q5, q95))
    cols = model.projected(data)
    X = np.hstack([base, cols])
    beta, r = lstsq(X, y)
    poly = ar_whitener(r)
    Xw = whiten(poly, X)
    rw = whiten(poly, r)
    s2 = float(rw @ rw) / max(1, len(rw) - X.shape[1])
    cov = s2 * np.linalg.pinv(Xw.T @ Xw)
    k = base.shape[1]
    return (AxisModel(axis, model.lo, model.hi, beta[k:], cov[k:, k:], model.freq_hz,
                      None if line0 is None else float(beta[m]), line0 or 0.0, model.inner,
                      model.bump, None if lean0 is None else float(beta[m + 1]),
                      lean0 or 0.0),
            beta[:m], float(r @ r))
