"""Predictions of a polynomial NARX model: one-step-ahead (Eq. 10 of Liu et al. 2005), model
predicted output / free run (Eq. 12) and k-step-ahead.

Indexing: ``y[k]`` and ``u[k]`` are the samples stamped k (u(k) acts from k to
k+1, so a model with delay 1 uses u(k-1) for y(k)). With L = ``model.max_lag``, a prediction
of y(k) needs the samples k-L .. k-1, so the first L outputs of every prediction are not
predictions: they are NaN in :func:`one_step_ahead` and :func:`k_step_ahead` (and for
k-step also the next k-1), and equal to the given initial outputs in :func:`free_run`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..terms.model import NarxModel

FloatArray = NDArray[np.float64]

#: free run stops as diverged once |yhat| exceeds this many times max(1, max|y_init|)
DIVERGENCE_FACTOR = 1e6


def _inputs(model: NarxModel, *arrays: FloatArray) -> list[FloatArray]:
    out = [np.asarray(a, dtype=np.float64) for a in arrays]
    n = len(out[0])
    for a in out:
        if a.ndim != 1 or len(a) != n:
            raise DataError("prediction: signals must be 1-D and of equal length")
        if not np.all(np.isfinite(a)):
            raise DataError("prediction: signals have non-finite samples")
    if not np.all(np.isfinite(model.estimates)):
        raise DataError("prediction: the model has non-finite estimates")
    return out


def one_step_ahead(model: NarxModel, y: FloatArray, u: FloatArray) -> FloatArray:
    """Eq. 10 of Liu et al. (2005): yhat(k) from measured y(k-i) and u(k-j); NaN for k < L."""
    y, u = _inputs(model, y, u)
    return _predict_from(model, lambda lag: _shifted(y, lag), u)


def _shifted(x: FloatArray, lag: int) -> FloatArray:
    """x(k - lag) for every k (NaN where k < lag)."""
    out = np.full(len(x), np.nan)
    if lag < len(x):
        out[lag:] = x[: len(x) - lag]
    return out


def _predict_from(
    model: NarxModel, y_lag: Callable[[int], FloatArray], u: FloatArray
) -> FloatArray:
    yhat = np.zeros(len(u))
    for term, theta in zip(model.terms, model.estimates, strict=True):
        val = np.full(len(u), float(theta))
        for var, lag in term.factors:
            val *= y_lag(lag) if var == "y" else _shifted(u, lag)
        yhat += val
    yhat[: min(model.max_lag, len(u))] = np.nan
    return yhat


def k_step_ahead(model: NarxModel, y: FloatArray, u: FloatArray, k: int) -> FloatArray:
    """yhat(t | t-k): start from measured outputs up to t-k, run the model k steps.

    Output lags i < h at horizon h use the predictions of the earlier horizons, lags >= h
    the measured y. NaN for t < L + k - 1. ``k = 1`` is :func:`one_step_ahead`.
    """
    if k < 1:
        raise DataError(f"k-step-ahead needs k >= 1 (got {k})")
    y, u = _inputs(model, y, u)
    preds: list[FloatArray] = []
    for h in range(1, k + 1):

        def y_lag(lag: int, h: int = h) -> FloatArray:
            return _shifted(preds[h - lag - 1], lag) if lag < h else _shifted(y, lag)

        preds.append(_predict_from(model, y_lag, u))
    return preds[-1]


@dataclass(frozen=True)
class FreeRun:
    """Model predicted output (Eq. 12) and whether it diverged (then NaN from there on)."""

    y: FloatArray
    diverged: bool
    diverged_at: int | None


def _compiled(model: NarxModel) -> list[tuple[float, tuple[int, ...], tuple[int, ...]]]:
    pairs = zip(model.terms, model.estimates, strict=True)
    return [(float(th), t.y_lags, t.u_lags) for t, th in pairs]


_Structure = tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]


@lru_cache(maxsize=512)
def _recursion(key: _Structure) -> Callable[..., int]:
    """The free run's loop for one model structure (the (output lags, input lags) of each
    term), unrolled into one Python function: term by term in the model's order, each
    term's factors multiplied left to right after its estimate (theta * y(k-i)... *
    u(k-j)...) and added to 0.0 in order, so the numbers are those of the plain loop bit
    for bit. A term without output factors is read from an array the caller computed
    (elementwise, in the same order). ``_run(y, exo, u, bound, start, *estimates)`` fills
    ``y`` from ``start`` on and returns the first sample out of bounds, or -1."""
    parts = []
    for i, (ylags, ulags) in enumerate(key):
        if not ylags:
            parts.append(f"e{i}[k]")
        else:
            parts.append("*".join([f"t{i}", *(f"y[k-{a}]" for a in ylags),
                                   *(f"u[k-{b}]" for b in ulags)]))
    args = "".join(f", t{i}" for i in range(len(key)))
    pure = "".join(f"    e{i} = exo[{i}]\n" for i, (ylags, _) in enumerate(key) if not ylags)
    src = (f"def _run(y, exo, u, bound, start{args}):\n{pure}"
           f"    for k in range(start, len(y)):\n"
           f"        acc = {' + '.join(['0.0', *parts])}\n"
           f"        if not -bound <= acc <= bound:  # also catches NaN\n"
           f"            return k\n"
           f"        y[k] = acc\n"
           f"    return -1\n")
    scope: dict[str, Callable[..., int]] = {}
    exec(compile(src, f"<free run of {len(key)} terms>", "exec"), scope)
    return scope["_run"]


def simulate(
    model: NarxModel, u: FloatArray, y_init: FloatArray, limit: float | None = None
) -> FreeRun:
    """Eq. 12 of Liu et al. (2005): the model fed its own past outputs and the measured input.

    ``y_init`` holds at least L measured outputs: the first L become yhat[:L]. If |yhat|
    exceeds ``limit`` (default 1e6 * max(1, max|y_init[:L]|)) or is not finite, the run
    stops there: ``diverged`` is set and the rest of ``y`` is NaN (no overflow arithmetic).
    """
    (u,) = _inputs(model, u)
    lag = model.max_lag
    y0 = np.asarray(y_init, dtype=np.float64)[:lag]
    if len(y0) < lag or not np.all(np.isfinite(y0)):
        raise DataError(f"free run needs {lag} finite initial outputs (got {len(y0)})")
    if len(u) < lag:
        raise DataError(f"free run needs at least {lag} input samples (got {len(u)})")
    scale = max(1.0, float(np.max(np.abs(y0), initial=0.0)))
    bound = limit if limit is not None else DIVERGENCE_FACTOR * scale
    terms = _compiled(model)
    thetas = [theta for theta, _, _ in terms]
    fn = _recursion(tuple((ylags, ulags) for _, ylags, ulags in terms))
    n = len(u)
    exo: list[list[float] | None] = []
    for theta, term in zip(thetas, model.terms, strict=True):
        if term.y_lags:
            exo.append(None)
            continue
        v = np.full(n, theta)
        for j in term.u_lags:
            v[j:] *= u[: n - j]
        exo.append(v.tolist())
    yl: list[float] = [*y0.tolist(), *([0.0] * (n - lag))]
    stop = fn(yl, exo, u.tolist(), bound, lag, *thetas)
    if stop >= 0:
        out = np.array(yl[:stop] + [np.nan] * (n - stop))
        return FreeRun(y=out, diverged=True, diverged_at=stop)
    return FreeRun(y=np.array(yl), diverged=False, diverged_at=None)


def free_run(model: NarxModel, u: FloatArray, y_init: FloatArray) -> FloatArray:
    """Model predicted output (Eq. 12); after a divergence the samples are NaN.

    Use :func:`simulate` to get the divergence flag and index explicitly.
    """
    return simulate(model, u, y_init).y
