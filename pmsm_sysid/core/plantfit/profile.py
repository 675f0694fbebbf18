"""How far a recording pins a Stribeck hump down: the profile of the fit over its velocity.

A hump ``S exp(-(v/vs)²) sign(v)`` is seen through the speeds the recording visits. Slow
motion that stays below vs, or a fast crossing of the hump, shows only a combination of the
static force S and the velocity vs (about their moment ``S vs²`` when the speed crosses
fast, about S when it dwells far below vs): a smaller vs with a larger S fits nearly as well.
The profile answers how far: for Stribeck velocities on a log grid around the fitted one,
every linear coefficient (S, the Coulomb level, the others) is refitted with the other
nonlinear parameters held, and the whitened residual energy is compared with the best
(``Δχ² = ΔSSE / s²``, the measure of the look-alike comparisons of :mod:`.modelling`).
The velocities within ``Δχ² < 3.84`` of the best (χ²₁ at 5 %) are those the data cannot
tell apart; along them S traces the data's own trade-off curve. When that region spans
more than a factor of two in vs (or reaches the end of the grid), the two are reported as
not identified, and the pair reported is the best point of that curve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .estimate import Fit, design, refine, whitened_sse
from .kinematics import EquationData
from .library import Effect, columns, stribeck_grid
from .select import share_of
from .stats import ar_whitener, lstsq, nested_f_test

FloatArray = NDArray[np.float64]

SPAN = 8.0  # the grid runs from vs/SPAN to vs*SPAN
POINTS = 25
CHI2_1_95 = 3.84
IDENTIFIED_RATIO = 2.0  # a region narrower than this factor in vs identifies it


@dataclass(frozen=True)
class Profile:
    """The fit over the Stribeck velocity: grid, static force along it, Δχ² to the best."""

    velocity_mps: tuple[float, ...]
    static_n: tuple[float, ...]
    delta_chi2: tuple[float, ...]

    def region(self) -> tuple[int, int]:
        """First and last grid index of the contiguous Δχ² < 3.84 region around the best."""
        d = np.asarray(self.delta_chi2)
        k = int(np.argmin(d))
        a = b = k
        while a > 0 and d[a - 1] < CHI2_1_95:
            a -= 1
        while b < len(d) - 1 and d[b + 1] < CHI2_1_95:
            b += 1
        return a, b

    @property
    def identified(self) -> bool:
        a, b = self.region()
        open_ended = a == 0 or b == len(self.velocity_mps) - 1
        return not open_ended and self.velocity_mps[b] / self.velocity_mps[a] <= IDENTIFIED_RATIO

    def note(self) -> str:
        a, b = self.region()
        v, s = self.velocity_mps, self.static_n
        edge = " (and beyond: the grid's end)" if a == 0 or b == len(v) - 1 else ""
        return (f"static force and Stribeck velocity trade off in this recording: every "
                f"velocity from {v[a] * 1e3:.3g} to {v[b] * 1e3:.3g} mm/s{edge} fits within "
                f"Δχ² < {CHI2_1_95} of the best, the static force going from "
                f"{s[a]:.3g} to {s[b]:.3g} N along that curve -- the two are not identified "
                "apart; motion that spans the hump, from standstill to well above its "
                "velocity, would tell them")

    def to_dict(self) -> dict[str, object]:
        a, b = self.region()
        return {"velocity_mps": list(self.velocity_mps), "static_n": list(self.static_n),
                "delta_chi2": list(self.delta_chi2), "identified": self.identified,
                "velocity_range_mps": [self.velocity_mps[a], self.velocity_mps[b]],
                "static_range_n": [self.static_n[a], self.static_n[b]]}


def _at(fit: Fit, k: int, vs: float, data: EquationData) -> tuple[float, float]:
    """(whitened SSE, static force) with effect k's velocity set to ``vs``."""
    effects = (*fit.effects[:k], replace(fit.effects[k], velocity_mps=vs),
               *fit.effects[k + 1:])
    X, fixed = design(effects, data)
    beta, _ = lstsq(X, data.y - fixed)
    return whitened_sse(effects, data, fit.poly), float(beta[fit.slices()[k]][0])


def stribeck_profile(fit: Fit, k: int, data: EquationData) -> tuple[Fit, Profile]:
    """The profile of ``fit`` over the velocity of its Stribeck effect ``k``; when a grid
    point among the velocities the data can place (:func:`_visited`) fits better than the
    refined velocity (the refinement only searches a factor of two around its start), the
    fit is refined again from there."""
    vs0 = fit.effects[k].velocity_mps
    grid = np.geomspace(vs0 / SPAN, vs0 * SPAN, POINTS)
    points = [_at(fit, k, float(v), data) for v in grid]
    best = _at(fit, k, vs0, data)[0]
    lo, hi = _visited(data)
    inside = [i for i, v in enumerate(grid) if lo <= v <= hi]
    j = min(inside, key=lambda i: points[i][0]) if inside else int(np.argmin(grid))
    if inside and points[j][0] < best - 1e-9 * max(best, 1e-300):
        moved = (*fit.effects[:k], replace(fit.effects[k], velocity_mps=float(grid[j])),
                 *fit.effects[k + 1:])
        fit = refine(moved, data, fit.poly)
        vs0 = fit.effects[k].velocity_mps
        best = _at(fit, k, vs0, data)[0]
    grid = np.sort(np.append(grid, vs0))
    points = [_at(fit, k, float(v), data) for v in grid]
    s2 = max(fit.sigma2, 1e-300)
    low = min(best, min(p[0] for p in points))
    return fit, Profile(tuple(float(v) for v in grid), tuple(p[1] for p in points),
                        tuple(max(0.0, (p[0] - low) / s2) for p in points))


def profiles(fit: Fit, data: EquationData) -> tuple[Fit, dict[int, Profile]]:
    """Profiles of every Stribeck effect of ``fit`` (the fit possibly moved to a better
    velocity, see :func:`stribeck_profile`)."""
    out: dict[int, Profile] = {}
    for k, e in enumerate(fit.effects):
        if e.name == "stribeck_friction" and math.isfinite(e.velocity_mps) \
                and e.velocity_mps > 0:
            fit, out[k] = stribeck_profile(fit, k, data)
    return fit, out


FRICTION = ("coulomb_friction", "viscous_error", "stribeck_friction")


def settle_friction(effects: tuple[Effect, ...], data: EquationData, n_tests: float,
                    alpha: float, min_share: float) -> tuple[Effect, ...]:
    """The friction curve of a selection with a Stribeck hump, fitted as a whole.

    Forward selection takes friction apart greedily, each term at a grid velocity: under
    slow motion a hump at a velocity too high took the Coulomb level's place and a viscous
    change patched the rest (0.31 N at 12.7 mm/s plus 4.4 N s/m, both 'high', for 0.15 N
    Coulomb plus 0.20 N at 8 mm/s). Here the Coulomb level, the viscous change and the hump
    are fitted together at every velocity the data can place (:func:`_visited`), the best
    is kept,
    and each friction term must then pass the selection's own test (significant against
    ``n_tests`` candidates at ``alpha`` and ``min_share`` of the mismatch) beside the others;
    of those that fail, a viscous change leaves first, then the Coulomb level (the
    simpler, more common effect wins a tie, as in :mod:`.modelling`).
    """
    k = next((i for i, e in enumerate(effects) if e.name == "stribeck_friction"), None)
    if k is None:
        return effects
    others = tuple(e for e in effects if e.name not in FRICTION)
    family = [Effect("coulomb_friction"), Effect("viscous_error")]
    lo, hi = _visited(data)
    X, fixed = design(effects, data)
    poly = ar_whitener(lstsq(X, data.y - fixed)[1])
    best: tuple[float, float] | None = None
    for vs in np.geomspace(lo, max(hi, lo), POINTS):
        trial = (*others, *family, Effect("stribeck_friction", velocity_mps=float(vs)))
        sse = whitened_sse(trial, data, poly)
        if best is None or sse < best[0]:
            best = (sse, float(vs))
    assert best is not None
    chosen = [Effect("viscous_error"), Effect("coulomb_friction"),
              Effect("stribeck_friction", velocity_mps=best[1])]
    while True:
        failing = [e for e in chosen if not _passes(e, [c for c in chosen if c is not e],
                                                    others, data, n_tests, alpha, min_share)]
        if not failing:
            break
        chosen.remove(failing[0])  # the viscous change first, then Coulomb, then the hump
    kept = {e.name: e for e in chosen}
    out = [kept.pop(e.name) if e.name in kept else e for e in effects
           if e.name not in FRICTION or e.name in kept]
    return (*out, *kept.values())


def _passes(e: Effect, rest: list[Effect], others: tuple[Effect, ...], data: EquationData,
            n_tests: float, alpha: float, min_share: float) -> bool:
    """The selection's test of ``e`` beside ``others`` and ``rest``."""
    base, fixed = design((*others, *rest), data)
    col = columns(e, data)
    y = data.y - fixed
    test = nested_f_test(y, base, col)
    return (test.corrected_log10_p(n_tests) < math.log10(alpha)
            and share_of(y, base, col, float(data.y @ data.y)) >= min_share)


def _visited(data: EquationData) -> tuple[float, float]:
    """The Stribeck velocities the data can place: the selection's grid (from three
    smoothing widths to half the speeds met, :func:`.library.stribeck_grid`); a hump wider
    than the speeds met is only a curvature of the friction over them."""
    grid, _ = stribeck_grid(data)
    if len(grid) == 0:
        return 3e-3, 3e-3
    return float(grid[0]), float(grid[-1])
