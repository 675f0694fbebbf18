"""Two fitted plants side by side: which parameters differ, against both uncertainties.

The simulator's plant and the real drive's are each fitted from their own recording
(:mod:`pmsm_sysid.core.plantfit.physical`), so each parameter carries its own standard
error. A parameter differs when the difference is large against the *combined* error,
``z = (θ_real - θ_sim) / sqrt(σ_real² + σ_sim²)``: a short, noisy simulated recording gives
an uncertain plant, and a difference it cannot resolve is no change.

An effect only one plant has is compared with what the other recording says about it --
its cross-estimate (:mod:`pmsm_sysid.core.plantfit.crossfit`), the effect fitted there with
the first plant's pitch or velocity held -- not with zero. A cogging or a thrust ripple
only one side has is tested on its sine/cosine coefficients at that pitch (χ², two degrees
of freedom: the amplitude of a force that is not there is biased upwards by noise). A
thrust lag or delay is compared only between two open-loop recordings: under feedback the
thrust answers the sensor noise and a lag cannot be told from it.

Every test made is counted, and the p-values are Bonferroni-corrected over them; a row is
reported when the corrected p is below ``alpha``. Its confidence follows ``diagnose``'s
evidence levels: ``high`` needs −log10 p ≥ 10 and the effect named at 'high' on the side(s)
that have it; a row whose effect was named only at 'low' is 'low'; else 'moderate'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..plantfit.crossfit import Cross, cross_estimates
from ..plantfit.found import SIGNIFICANCE_CAP, FoundEffect
from ..plantfit.physical import PhysicalFit
from ..plantfit.translate import _polar

FloatArray = NDArray[np.float64]

HIGH_SIGNIFICANCE = 10.0
LAG_FAMILY = ("thrust_lag", "transport_delay")
#: The parameters compared when both plants have the effect (the first is the effect's size).
PARAMS = {"force_offset": ("amplitude_n",), "coulomb_friction": ("amplitude_n",),
          "spring": ("stiffness_n_per_m",), "stribeck_friction": ("static_n", "velocity_mps"),
          "thrust_lag": ("tau_s",), "transport_delay": ("delay_s",),
          "cogging": ("amplitude_n", "pitch_m", "phase_rad"),
          "thrust_ripple": ("relative", "pitch_m", "phase_rad")}
RIGID_PARAMS = {"mass_error": "mass_kg", "viscous_error": "viscous_n_per_mps"}
PERIODIC = ("cogging", "thrust_ripple")


@dataclass(frozen=True)
class Change:
    """One parameter that differs (or one periodic force only one side has)."""

    effect: str
    param: str
    sim: float | None
    real: float | None
    std: float
    z: float
    significance: float
    confidence: str = "moderate"
    absent_estimate: tuple[float, float] | None = None
    """Where one side has no such effect: what its recording says (value, std)."""

    @property
    def parameter(self) -> str:
        return self.param if self.effect in RIGID_PARAMS else f"{self.effect}.{self.param}"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"parameter": self.parameter, "sim": self.sim, "real": self.real,
                               "std": self.std, "confidence": self.confidence,
                               "significance": self.significance, "z": self.z}
        if self.absent_estimate is not None:
            out["absent_side_estimate"] = {"value": self.absent_estimate[0],
                                           "std": self.absent_estimate[1]}
        return out


@dataclass(frozen=True)
class _Test:
    effect: str
    param: str
    sim: float | None
    real: float | None
    std: float
    z: float
    log10_p: float  # uncorrected
    absent: tuple[float, float] | None = None


def _scalar(effect: str, param: str, sim: tuple[float, float] | None,
            real: tuple[float, float] | None, cross: tuple[float, float] | None) -> _Test:
    """z-test of real - sim; the side without the effect enters with its cross-estimate."""
    s = sim if sim is not None else cross
    r = real if real is not None else cross
    assert s is not None and r is not None
    sd = math.hypot(s[1], r[1])
    z = (r[0] - s[0]) / sd if sd > 0 else 0.0
    logp = float(stats.norm.logsf(abs(z)) + math.log(2.0)) / math.log(10.0)
    return _Test(effect, param, None if sim is None else sim[0], None if real is None
                 else real[0], sd, z, logp, cross if (sim is None or real is None) else None)


def _value(pf: PhysicalFit, effect: str, param: str) -> tuple[float, float]:
    """A fitted parameter and its standard error (nan when the fit has none)."""
    if effect in RIGID_PARAMS:
        return float(getattr(pf.plant, param)), float(pf.std[param])
    block = getattr(pf.plant, effect)
    return float(getattr(block, param)), float(pf.std[effect].get(param, math.nan))


def _fundamental(pf: PhysicalFit, name: str) -> tuple[FloatArray, FloatArray]:
    """Sine/cosine coefficients of a periodic effect's fundamental and their covariance."""
    k = next(i for i, e in enumerate(pf.joint.effects) if e.name == name)
    e = pf.joint.effects[k]
    b, cov = pf.joint.beta[pf.joint.slices()[k]], pf.joint.beta_cov(k)
    j = e.orders.index(1) if name == "cogging" else 0
    sl = slice(2 * j, 2 * j + 2)
    return b[sl], cov[sl, sl]


def _periodic(name: str, present: PhysicalFit, cross: Cross, sim_has: bool) -> _Test:
    """χ² (2 dof) of the fundamental's coefficients: present side against the other's
    cross-estimate at the same pitch."""
    bp, cp = _fundamental(present, name)
    d = bp - cross.beta[:2]
    S = cp + cross.cov[:2, :2]
    chi2 = float(d @ np.linalg.pinv(S) @ d)
    logp = float(stats.chi2.logsf(chi2, 2)) / math.log(10.0)
    sign = -1.0 if name == "thrust_ripple" else 1.0
    amp, _, sa, _ = _polar(sign * bp, cp)
    amp_x, _, sa_x, _ = _polar(sign * cross.beta[:2], cross.cov[:2, :2])
    key = PARAMS[name][0]
    sd = math.hypot(sa, sa_x)
    z = math.sqrt(chi2) if not sim_has else -math.sqrt(chi2)
    return _Test(name, key, amp if sim_has else None, None if sim_has else amp, sd, z, logp,
                 (amp_x, sa_x))


def _pair_tests(name: str, sim: PhysicalFit, real: PhysicalFit) -> list[_Test]:
    """Both plants have the effect: one z-test per parameter (a phase only when the
    pitches agree: at another pitch a phase means nothing)."""
    out: list[_Test] = []
    for param in PARAMS[name]:
        if param == "phase_rad" and out and any(abs(t.z) > 2.0 for t in out
                                                if t.param == "pitch_m"):
            continue
        s, r = _value(sim, name, param), _value(real, name, param)
        if param == "phase_rad":  # the difference wrapped to (-π, π]
            r = (s[0] + math.remainder(r[0] - s[0], 2.0 * math.pi), r[1])
        if not (math.isfinite(s[1]) and math.isfinite(r[1])):
            continue
        out.append(_scalar(name, param, s, r, None))
    return out


def _one_sided(name: str, present: PhysicalFit, cross: Cross, sim_has: bool) -> _Test:
    if name in PERIODIC:
        return _periodic(name, present, cross, sim_has)
    param = PARAMS[name][0]
    mine = _value(present, name, param)
    other = (float(cross.beta[0]), math.sqrt(max(float(cross.cov[0, 0]), 0.0)))
    return _scalar(name, param, mine if sim_has else None, None if sim_has else mine, other)


def _open(pf: PhysicalFit) -> bool:
    return not pf.setup.closed


def compare(sim: PhysicalFit, real: PhysicalFit, alpha: float,
            ) -> tuple[list[Change], list[str], int]:
    """The changes between the two fitted plants (module doc), notes, tests made."""
    notes: list[str] = []
    tests = [_scalar(e, p, _value(sim, e, p), _value(real, e, p), None)
             for e, p in RIGID_PARAMS.items()]
    s_names = [e.name for e in sim.effects]
    r_names = [e.name for e in real.effects]
    both_open = _open(sim) and _open(real)
    only_r = [e for e in real.effects if e.name not in s_names
              and (both_open or e.name not in LAG_FAMILY)]
    only_s = [e for e in sim.effects if e.name not in r_names
              and (both_open or e.name not in LAG_FAMILY)]
    for e in (*real.effects, *sim.effects):
        if e.name in LAG_FAMILY and not both_open and not (e.name in s_names
                                                           and e.name in r_names):
            side = "simulation's" if e.name in s_names else "real drive's"
            notes.append(f"{e.name} in the {side} recording is not compared: a closed-loop "
                         "recording cannot tell a lag from the loop's answer to noise")
    cross_s = dict(zip([e.name for e in only_r], cross_estimates(sim, tuple(only_r)),
                       strict=True))
    cross_r = dict(zip([e.name for e in only_s], cross_estimates(real, tuple(only_s)),
                       strict=True))
    for name in dict.fromkeys(s_names + r_names):
        if name in s_names and name in r_names:
            tests += _pair_tests(name, sim, real)
        elif name in cross_s:
            tests.append(_one_sided(name, real, cross_s[name], sim_has=False))
        elif name in cross_r:
            tests.append(_one_sided(name, sim, cross_r[name], sim_has=True))
    n = len(tests)
    rows = []
    for t in tests:
        sig = _significance(t.log10_p, n)
        if sig >= -math.log10(alpha):
            rows.append(Change(t.effect, t.param, t.sim, t.real, t.std, t.z, sig,
                               _confidence(sig, t.effect, sim, real), t.absent))
        elif t.absent is not None:
            notes.append(_unresolved(t))
    return rows, notes, n


def _significance(log10_p: float, n_tests: int) -> float:
    """-log10 of the Bonferroni-corrected p-value, capped like diagnose's."""
    if not math.isfinite(log10_p):
        return SIGNIFICANCE_CAP
    return float(min(SIGNIFICANCE_CAP, max(0.0, -(log10_p + math.log10(max(n_tests, 1))))))


RANK = {"low": 0, "moderate": 1, "high": 2}


def _confidence(sig: float, effect: str, sim: PhysicalFit, real: PhysicalFit) -> str:
    named = [f.confidence for pf in (sim, real) for f in pf.found if f.name == effect]
    weakest = min(named, key=lambda c: RANK[c]) if named else "high"
    if weakest == "low":
        return "low"
    return "high" if sig >= HIGH_SIGNIFICANCE and weakest == "high" else "moderate"


def _unresolved(t: _Test) -> str:
    side, other = ("real drive's", "simulation's") if t.sim is None else \
        ("simulation's", "real drive's")
    value = t.real if t.sim is None else t.sim
    assert t.absent is not None
    return (f"{t.effect}: found in the {side} recording ({t.param} {value:.4g}) and not "
            f"ruled out by the {other} ({t.absent[0]:.3g} ± {t.absent[1]:.2g} there): not a "
            "change")


def found_by_name(pf: PhysicalFit) -> dict[str, FoundEffect]:
    """The named effects of a fitted plant by name."""
    return {f.name: f for f in pf.found}


__all__ = ["Change", "compare", "found_by_name"]
