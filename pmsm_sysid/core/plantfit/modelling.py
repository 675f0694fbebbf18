"""From the selected effects to a refined, disambiguated, held-out-confirmed model.

1. The linear thrust-derivative regressor becomes an exact first-order lag with τ started
   at its coefficient, and all nonlinear parameters are refined (:mod:`.estimate`).
2. Cogging harmonics are re-tested at the refined pitch (:func:`.select.grow_cogging`).
3. Look-alikes are told apart by the whitened residual energy of the two refined models
   with the same number of parameters, Δχ² = ΔSSE / s²: a transport delay replaces the lag
   only if it fits better by Δχ² > 3.84 (χ²₁ at 5 %), and Coulomb friction replaces a
   lone Stribeck term unless the hump fits better by that margin -- the simpler, more
   common effect wins a tie, and the margin is reported.
4. Held-out confirmation: every effect must reduce the mean-square equation error on data
   it was not fitted on; the weakest failure is dropped and the model rebuilt until all
   pass. How surely it does (Diebold-Mariano, one-sided) sets the reported confidence: a
   short held-out segment may confirm a small effect without statistical force.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .estimate import Fit, contributions, design, refine, whitened_sse
from .kinematics import EquationData
from .library import Effect
from .select import ALPHA, MIN_SHARE, grow_cogging
from .stats import HeldOutTest, ar_whitener, held_out_test, lstsq

FloatArray = NDArray[np.float64]

CHI2_1_95 = 3.84


@dataclass(frozen=True)
class Alternative:
    """A look-alike effect that was fitted and compared: Δχ² > 0 means it fits worse."""

    name: str
    delta_chi2: float
    value: float

    def to_dict(self) -> dict[str, float | str]:
        return {"name": self.name, "delta_chi2": self.delta_chi2, "value": self.value}


@dataclass(frozen=True)
class Model:
    """The refined model with its look-alike comparisons."""

    fit: Fit
    alternatives: dict[str, Alternative]


def _poly_for(effects: tuple[Effect, ...], data: EquationData) -> FloatArray:
    X, fixed = design(effects, data)
    _, e = lstsq(X, data.y - fixed)
    return ar_whitener(e)


def _dynamic_start(effects: tuple[Effect, ...], data: EquationData) -> tuple[Effect, ...]:
    """Turn the linear lag regressor into an exact lag, τ started at its coefficient."""
    if not any(e.name == "thrust_lag" and not e.dynamic for e in effects):
        return effects
    X, fixed = design(effects, data)
    beta, _ = lstsq(X, data.y - fixed)
    out, i = [], 0
    for e in effects:
        if not e.dynamic and e.name == "thrust_lag":
            out.append(replace(e, tau_s=max(float(beta[i]), 0.1 * data.period)))
        else:
            out.append(e)
        i += 0 if e.dynamic else e.width
    return tuple(out)


def _add_cogging_orders(fit: Fit, data: EquationData, alpha: float,
                        min_share: float) -> tuple[Effect, ...]:
    """Effects with the cogging harmonics re-tested at the refined pitch."""
    effects = fit.effects
    idx = [i for i, e in enumerate(effects) if e.name == "cogging"]
    if not idx:
        return effects
    k = idx[0]
    others = (*effects[:k], *effects[k + 1:])
    X, fixed = design(others, data)
    cog = replace(effects[k], orders=(1,)) if 1 in effects[k].orders else effects[k]
    grown = grow_cogging(cog, data, X, data.y - fixed, alpha, min_share)
    return (*effects[:k], grown, *effects[k + 1:])


def _swap(effects: tuple[Effect, ...], k: int, other: Effect) -> tuple[Effect, ...]:
    return (*effects[:k], other, *effects[k + 1:])


def _compare(fit: Fit, data: EquationData, k: int, other: Effect,
             prefer_current: bool) -> tuple[Fit, Alternative]:
    """Refit with effect k replaced by ``other``; keep the better (ties to the preferred)."""
    alt = refine(_swap(fit.effects, k, other), data, fit.poly)
    sse_cur = whitened_sse(fit.effects, data, fit.poly)
    sse_alt = whitened_sse(alt.effects, data, fit.poly)
    margin = (sse_cur - sse_alt) / fit.sigma2  # > 0: the alternative fits better
    switch = margin > CHI2_1_95 if prefer_current else margin > -CHI2_1_95
    if switch:
        e = fit.effects[k]
        return alt, Alternative(e.name, margin, _value(e))
    return fit, Alternative(other.name, -margin, _value(alt.effects[k]))


def _value(e: Effect) -> float:
    if e.tau_s >= 0:
        return e.tau_s
    if e.delay_s >= 0:
        return e.delay_s
    return e.velocity_mps if e.name == "stribeck_friction" else 0.0


def build_model(effects: tuple[Effect, ...], data: EquationData,
                alpha: float = ALPHA, min_share: float = MIN_SHARE) -> Model:
    """Steps 1-3 of the module doc on the estimation data."""
    if not effects:
        poly = _poly_for(effects, data)
        return Model(refine(effects, data, poly), {})
    start = _dynamic_start(effects, data)
    fit = refine(start, data, _poly_for(start, data))
    grown = _add_cogging_orders(fit, data, alpha, min_share)
    if grown != fit.effects:
        fit = refine(grown, data, fit.poly)
    alts: dict[str, Alternative] = {}
    names = [e.name for e in fit.effects]
    for k, e in enumerate(fit.effects):
        if e.name == "thrust_lag":
            delay = Effect("transport_delay", delay_s=max(e.tau_s, 0.1 * data.period))
            fit, alts["thrust_lag"] = _compare(fit, data, k, delay, prefer_current=True)
        if e.name == "stribeck_friction" and "coulomb_friction" not in names:
            fit, alts["stribeck_friction"] = _compare(fit, data, k, Effect("coulomb_friction"),
                                                      prefer_current=False)
    return Model(fit, alts)


def held_out(fit: Fit, data: EquationData) -> list[HeldOutTest]:
    """Diebold-Mariano test of each effect on data the model was not fitted on."""
    parts = contributions(fit, data)
    e_all = data.y - np.sum(parts, axis=0) if parts else data.y
    poly = ar_whitener(e_all)
    return [held_out_test(e_all + c, e_all, poly) for c in parts]


def confirmed_model(effects: tuple[Effect, ...], est: EquationData, val: EquationData,
                    alpha: float = ALPHA, min_share: float = MIN_SHARE,
                    ) -> tuple[Model, list[HeldOutTest], list[Effect]]:
    """Build, confirm on ``val``, drop the weakest unconfirmed effect, repeat (step 4)."""
    dropped: list[Effect] = []
    current = effects
    while True:
        model = build_model(current, est, alpha, min_share)
        tests = held_out(model.fit, val)
        failing = [(t.z, i) for i, t in enumerate(tests) if not t.confirmed]
        if not failing:
            return model, tests, dropped
        _, worst = min(failing)
        name = model.fit.effects[worst].name
        dropped.append(model.fit.effects[worst])
        current = tuple(e for e in current if e.name != name
                        and not (name == "transport_delay" and e.name == "thrust_lag"))
