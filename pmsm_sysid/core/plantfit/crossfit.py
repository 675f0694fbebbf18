"""An effect another recording showed, estimated on this one: the cross-estimate.

Comparing two fitted plants parameter by parameter needs, for an effect only one of them
has, what the other recording says about it: not "absent" but "0.05 ± 0.2 N", so that a
short, noisy recording that cannot rule the effect out does not count as evidence that it
is missing. The effect is added to this recording's fitted plant with the other
recording's nonlinear parameters held (its pitch, its Stribeck velocity) and everything is
re-estimated linearly; a lag or a delay enters as the linear thrust-derivative regressor,
whose coefficient is the time constant to first order. Standard errors are the sandwich
covariance under the residual's AR noise model, as in :mod:`.estimate`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from .estimate import design
from .kinematics import EquationData
from .library import Effect
from .physical import PhysicalFit
from .stats import ar_whitener, lstsq, whiten

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Cross:
    """The linear coefficients of one added effect and their covariance."""

    effect: Effect
    beta: FloatArray
    cov: FloatArray


def linearised(e: Effect) -> Effect:
    """``e`` with its nonlinear parameters held, as linear columns only: an exact lag or
    delay becomes the thrust-derivative regressor, a cogging its fundamental."""
    if e.name in ("thrust_lag", "transport_delay"):
        return Effect("thrust_lag")
    if e.name == "cogging":
        return replace(e, orders=(1,))
    return e


def linear_fit(effects: tuple[Effect, ...], data: EquationData,
               ) -> tuple[FloatArray, FloatArray]:
    """Least-squares coefficients of ``effects`` (nonlinear parameters as given) and their
    sandwich covariance under the residual's AR(p) model."""
    X, fixed = design(effects, data)
    beta, r = lstsq(X, data.y - fixed)
    poly = ar_whitener(r)
    rw = whiten(poly, r)
    sigma2 = float(rw @ rw) / max(1, len(rw) - X.shape[1])
    G = lfilter([1.0], poly, X[::-1], axis=0)[::-1]
    bread = np.linalg.pinv(X.T @ X)
    cov: FloatArray = sigma2 * bread @ (G.T @ G) @ bread
    return beta, cov


def cross_estimates(pf: PhysicalFit, others: tuple[Effect, ...]) -> list[Cross]:
    """Each of ``others`` estimated on ``pf``'s recording beside its own plant (module doc)."""
    if not others:
        return []
    added = tuple(linearised(e) for e in others)
    effects = pf.joint.effects + added
    beta, cov = linear_fit(effects, pf.data)
    out, i = [], sum(e.width for e in pf.joint.effects)
    for e in added:
        s = slice(i, i + e.width)
        out.append(Cross(e, beta[s], cov[s, s]))
        i += e.width
    return out


__all__ = ["Cross", "cross_estimates", "linear_fit", "linearised"]
