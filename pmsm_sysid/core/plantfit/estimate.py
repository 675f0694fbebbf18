"""Nonlinear refinement of the chosen effects: pitch, Stribeck velocity, lag τ, delay.

The forward regression fixes each nonlinear parameter on a grid. Here they are refined
jointly by variable projection: for a trial vector η the linear coefficients β are the
ordinary least-squares solution, and ``scipy.optimize.least_squares`` moves η to minimise
the residual energy. A thrust lag and a transport delay enter exactly through
:func:`.kinematics.interval_force` with no free gain.

The estimates are ordinary least squares on the filtered data, as IDIM-LS is: weighting by
the noise colour (GLS) would be more efficient if the library were exact, but it stresses the
fast transients (friction reversals), where real physics departs most from any library
shape, and biases the parameters there. The colour is used for the uncertainty instead: with
J the Jacobian of the residual with respect to all parameters (β exactly, η by central
differences) and the AR model of the residual (:mod:`.stats`) standing for its covariance Σ,
``cov = (JᵀJ)⁻¹ JᵀΣJ (JᵀJ)⁻¹`` -- a sandwich (parametric HAC) covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import lfilter

from .kinematics import EquationData, thinned
from .library import (
    INSTRUMENTED,
    OVERSAMPLE,
    Effect,
    columns,
    dynamic_part,
    measured_columns,
)
from .stats import lstsq, whiten

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Fit:
    """A refined model: effects, linear coefficients, nonlinear parameters, covariance."""

    effects: tuple[Effect, ...]
    beta: FloatArray
    eta: FloatArray
    cov: FloatArray
    poly: FloatArray
    sigma2: float

    def slices(self) -> list[slice]:
        """Slice of ``beta`` belonging to each effect."""
        out, i = [], 0
        for e in self.effects:
            out.append(slice(i, i + e.width))
            i += e.width
        return out

    def eta_index(self) -> list[int | None]:
        """Index into ``eta`` of each effect's nonlinear parameter (None if it has none)."""
        out: list[int | None] = []
        i = 0
        for e in self.effects:
            if _has_eta(e):
                out.append(i)
                i += 1
            else:
                out.append(None)
        return out

    def beta_cov(self, k: int) -> FloatArray:
        """Covariance block of effect k's linear coefficients."""
        s = self.slices()[k]
        out: FloatArray = self.cov[s, s]
        return out

    def eta_std(self, k: int) -> float:
        """Standard error of effect k's nonlinear parameter (nan if none)."""
        j = self.eta_index()[k]
        if j is None:
            return float("nan")
        nb = len(self.beta)
        return float(math.sqrt(max(self.cov[nb + j, nb + j], 0.0)))


def _has_eta(e: Effect) -> bool:
    return e.name in ("cogging", "thrust_ripple", "stribeck_friction") or e.dynamic


def eta_of(e: Effect) -> float:
    """The effect's nonlinear parameter in the optimiser's units."""
    if e.name in ("cogging", "thrust_ripple"):
        return 1.0 / e.pitch_m  # wavenumber (1/m)
    if e.name == "stribeck_friction":
        return math.log(e.velocity_mps)
    return e.tau_s if e.tau_s >= 0 else e.delay_s


def with_eta(e: Effect, value: float) -> Effect:
    """The effect with its nonlinear parameter set from optimiser units."""
    if e.name in ("cogging", "thrust_ripple"):
        return replace(e, pitch_m=1.0 / value)
    if e.name == "stribeck_friction":
        return replace(e, velocity_mps=math.exp(value))
    if e.tau_s >= 0:
        return replace(e, tau_s=max(value, 0.0))
    return replace(e, delay_s=max(value, 0.0))


def _bounds(e: Effect, data: EquationData) -> tuple[float, float]:
    v = eta_of(e)
    if e.name in ("cogging", "thrust_ripple"):
        travel = float(np.ptp(thinned(data, data.x)))
        step = 1.0 / (OVERSAMPLE * travel)
        return max(v - 3 * step, 0.5 * v, 0.9 / travel), v + 3 * step
    if e.name == "stribeck_friction":
        return v - math.log(2.0), v + math.log(2.0)
    return 0.0, max(5.0 * v, 4.0 * data.period)


def design(effects: tuple[Effect, ...], data: EquationData) -> tuple[FloatArray, FloatArray]:
    """Linear regressor matrix and the fixed (lag/delay) part of the residual model."""
    cols = [columns(e, data) for e in effects if not e.dynamic]
    fixed = np.zeros(data.n)
    for e in effects:
        if e.dynamic:
            fixed = fixed + dynamic_part(e, data)
    X = np.hstack(cols) if cols else np.zeros((data.n, 0))
    return X, fixed


def contributions(fit: Fit, data: EquationData) -> list[FloatArray]:
    """Each effect's force on ``data`` (filtered, decimated) with the fitted parameters,
    made of the measured signals (:func:`.library.measured_columns`): what the corrected
    plant takes out of the equation error."""
    out = []
    for e, s in zip(fit.effects, fit.slices(), strict=True):
        if e.dynamic:
            out.append(measured_columns(e, data))
        else:
            out.append(measured_columns(e, data) @ fit.beta[s])
    return out


def remainder_of(fit: Fit, data: EquationData, keep: tuple[int, ...] | None = None,
                 ) -> FloatArray:
    """:func:`remainder` of the fit's effects (those indexed by ``keep``) on ``data``."""
    idx = range(len(fit.effects)) if keep is None else keep
    slices = fit.slices()
    effects = tuple(fit.effects[k] for k in idx)
    beta = np.concatenate([fit.beta[slices[k]] for k in idx]) if effects else np.zeros(0)
    return remainder(effects, beta, data)


def remainder(effects: tuple[Effect, ...], beta: FloatArray,
              data: EquationData) -> FloatArray:
    """What the instruments leave of the effects' force: measured minus estimation columns
    times the coefficients (zero for effects without instruments). ``y - fixed -
    remainder`` regressed on :func:`design` leaves the corrected plant's equation error."""
    out = np.zeros(data.n)
    i = 0
    for e in effects:
        if e.dynamic:
            out += measured_columns(e, data) - dynamic_part(e, data)
        elif e.name in INSTRUMENTED:
            b = beta[i:i + e.width]
            out += (measured_columns(e, data) - columns(e, data)) @ b
        i += 0 if e.dynamic else e.width
    return out


def _apply(effects: tuple[Effect, ...], eta: FloatArray) -> tuple[Effect, ...]:
    out, j = [], 0
    for e in effects:
        if _has_eta(e):
            out.append(with_eta(e, float(eta[j])))
            j += 1
        else:
            out.append(e)
    return tuple(out)


def _residual(effects: tuple[Effect, ...], data: EquationData,
              beta: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Least-squares coefficients (unless given) and the residual of ``effects``."""
    X, fixed = design(effects, data)
    y = data.y - fixed
    if beta is None:
        return lstsq(X, y)
    return beta, y - X @ beta


def refine(effects: tuple[Effect, ...], data: EquationData, poly: FloatArray) -> Fit:
    """Refine every nonlinear parameter jointly (variable projection), with covariance."""
    eta0 = np.array([eta_of(e) for e in effects if _has_eta(e)])
    if len(eta0):
        bounds = [_bounds(e, data) for e in effects if _has_eta(e)]
        lo = np.array([b[0] for b in bounds])
        hi = np.array([b[1] for b in bounds])
        x0 = np.clip(eta0, lo + 1e-12 * np.abs(lo), hi - 1e-12 * np.abs(hi))
        def fun(eta: FloatArray) -> FloatArray:
            return _residual(_apply(effects, eta), data)[1]

        res = least_squares(fun, x0, bounds=(lo, hi), x_scale=np.maximum(np.abs(x0), 1e-4),
                            diff_step=np.full(len(x0), 1e-4), max_nfev=200)
        eta = np.asarray(res.x, dtype=np.float64)
    else:
        eta = np.zeros(0)
    final = _apply(effects, eta)
    beta, r = _residual(final, data)
    rw = whiten(poly, r)
    sigma2 = float(rw @ rw) / max(1, len(rw) - len(beta) - len(eta))
    return Fit(final, beta, eta, _covariance(effects, data, poly, beta, eta, sigma2), poly,
               sigma2)


def _jacobian(effects: tuple[Effect, ...], data: EquationData, beta: FloatArray,
              eta: FloatArray) -> FloatArray:
    """d(residual)/d(beta, eta): -X exactly, eta by central differences."""
    X, _ = design(_apply(effects, eta), data)
    cols = [-X]
    for j in range(len(eta)):
        h = 1e-5 * max(abs(eta[j]), 1e-6)
        up, dn = eta.copy(), eta.copy()
        up[j] += h
        dn[j] = max(eta[j] - h, 0.0) if eta[j] >= 0 else eta[j] - h
        ru = _residual(_apply(effects, up), data, beta)[1]
        rd = _residual(_apply(effects, dn), data, beta)[1]
        cols.append(((ru - rd) / (up[j] - dn[j]))[:, None])
    return np.hstack(cols)


def _covariance(effects: tuple[Effect, ...], data: EquationData, poly: FloatArray,
                beta: FloatArray, eta: FloatArray, sigma2: float) -> FloatArray:
    """Sandwich covariance of (beta, eta) under AR(p) residuals (module doc)."""
    J = _jacobian(effects, data, beta, eta)
    # Σ = σ² (WᵀW)⁻¹ for the whitening W = A(q): JᵀΣJ = σ² GᵀG with G = W⁻ᵀ J, i.e. the
    # all-pole filter 1/A(q) run backwards in time over the columns of J.
    G = lfilter([1.0], poly, J[::-1], axis=0)[::-1]
    try:
        bread = np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        return np.full((J.shape[1], J.shape[1]), np.nan)
    cov: FloatArray = sigma2 * bread @ (G.T @ G) @ bread
    return cov


def whitened_sse(effects: tuple[Effect, ...], data: EquationData, poly: FloatArray) -> float:
    """Whitened residual energy of ``effects`` refitted linearly (nonlinear params as given)."""
    rw = whiten(poly, _residual(effects, data)[1])
    return float(rw @ rw)
