"""The changes between a simulator's plant and a real drive's, as effects and in words.

* :func:`apply_changes` -- the simulator's plant with the changes applied: each changed
  parameter takes the real drive's value, an effect only the real drive has is added with
  its block, an effect only the simulation has is removed. Everything else stays the
  simulator's.
* :func:`beyond_sim` / :func:`sim_only` -- the changes grouped by effect in the shape of
  ``diagnose``'s ``effects``: what the real drive has that the simulation lacks (as against a
  plant file: a mass or viscous error with the corrected value; for a force offset, Coulomb
  friction or a spring the amount to add; for the others the real drive's block), and what
  the simulation has that the real drive lacks.
* :func:`in_words` -- one sentence per change, side by side: "the real axis is 4 % heavier
  (3.22 ± 0.03 kg against 3.10 kg)".
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from ..physics.plant import Plant
from ..plantfit.found import FoundEffect
from ..plantfit.stats import HeldOutTest
from .changes import RIGID_PARAMS, Change
from .fitted import PlantFitResult

ADDITIVE = ("force_offset", "coulomb_friction", "spring")
LABEL = {"force_offset": "force offset", "coulomb_friction": "Coulomb friction",
         "spring": "spring", "stribeck_friction": "Stribeck friction", "cogging": "cogging",
         "thrust_ripple": "thrust ripple", "thrust_lag": "thrust lag",
         "transport_delay": "transport delay"}
#: How a parameter is said and shown: words, unit, scale from SI.
PARAM_WORDS = {"amplitude_n": ("amplitude", "N", 1.0), "static_n": ("static force", "N", 1.0),
               "velocity_mps": ("Stribeck velocity", "mm/s", 1e3),
               "pitch_m": ("pitch", "mm", 1e3), "phase_rad": ("phase", "rad", 1.0),
               "relative": ("ripple", "%", 100.0), "tau_s": ("time constant", "ms", 1e3),
               "delay_s": ("delay", "ms", 1e3),
               "stiffness_n_per_m": ("stiffness", "N/m", 1.0)}


@dataclass(frozen=True)
class SimComparison:
    """A simulator's recording against a real one: both fitted plants and their changes."""

    sim: PlantFitResult
    real: PlantFitResult
    changes: tuple[Change, ...]
    sim_only: tuple[FoundEffect, ...]
    tests: int

    def words(self) -> list[str]:
        """The changes side by side, one sentence each, with their confidence."""
        return [f"{in_words(c, self.sim.plant, self.real.plant)} [confidence {c.confidence}]"
                for c in self.changes]

    def to_dict(self) -> dict[str, Any]:
        return {"reference": "sim_recording",
                "sim_plant": {**self.sim.plant_dict(), "std": self.sim.std},
                "real_plant": {**self.real.plant_dict(), "std": self.real.std},
                "sim_only": [e.to_dict() for e in self.sim_only],
                "changes": [c.to_dict() for c in self.changes],
                "side_by_side": self.words(),
                "sim_fit": {"effects": [e.to_dict() for e in self.sim.effects],
                            "fit": self.sim.fit, "method": self.sim.method,
                            "notes": list(self.sim.notes)},
                "real_fit": {"effects": [e.to_dict() for e in self.real.effects],
                             "fit": self.real.fit, "notes": list(self.real.notes)}}

    def summary_lines(self) -> list[str]:
        """The two plants and the changes in words (the head of the summary)."""
        lines = [f"simulation's plant (fitted from its recording): {_plant_line(self.sim)}",
                 f"real drive's plant (fitted from its recording): {_plant_line(self.real)}"]
        words = self.words()
        if not words:
            lines.append("side by side: no significant difference -- the real drive's plant "
                         "matches the simulation's within their combined errors")
        else:
            lines.append("side by side:")
            lines += [f"  {w}" for w in words]
        return lines


def _plant_line(f: PlantFitResult) -> str:
    p, s = f.plant, f.std
    named = ", ".join(e.name for e in f.effects) or "none"
    return (f"mass {p.mass_kg:.4g} ± {s['mass_kg']:.2g} kg, viscous "
            f"{p.viscous_n_per_mps:.4g} ± {s['viscous_n_per_mps']:.2g} N·s/m; effects: {named}")


def _block(p: Plant, name: str) -> Any:
    return getattr(p, name)


def apply_changes(sim_plant: Plant, real_plant: Plant, rows: list[Change]) -> Plant:
    """``sim_plant`` with each change taking ``real_plant``'s value (module doc)."""
    p = sim_plant
    for r in rows:
        new: dict[str, Any]
        if r.effect in RIGID_PARAMS:
            new = {r.param: getattr(real_plant, r.param)}
        elif r.real is None:
            new = {r.effect: None}
        elif r.sim is None or _block(p, r.effect) is None:
            new = {r.effect: _block(real_plant, r.effect)}
        else:
            value = getattr(_block(real_plant, r.effect), r.param)
            new = {r.effect: replace(_block(p, r.effect), **{r.param: value})}
        p = replace(p, **new)
    return p


def groups(rows: list[Change]) -> dict[str, list[Change]]:
    """The rows by effect (``mass_error``/``viscous_error`` for the rigid parameters)."""
    out: dict[str, list[Change]] = {}
    for r in rows:
        out.setdefault(r.effect, []).append(r)
    return out


def _params(name: str, rows: list[Change], sim: Plant, real: Plant,
            found: FoundEffect | None) -> tuple[dict[str, Any], dict[str, float]]:
    """diagnose's parameters of the effect the simulation must take on (module doc)."""
    if name in RIGID_PARAMS:
        key = RIGID_PARAMS[name]
        now, was = float(getattr(real, key)), float(getattr(sim, key))
        return ({key: now, "change" + key[key.index("_"):]: now - was},
                {key: rows[0].std})
    if name in ADDITIVE:
        key = rows[0].param
        was = float(getattr(_block(sim, name), key)) if _block(sim, name) else 0.0
        return {key: float(getattr(_block(real, name), key)) - was}, {key: rows[0].std}
    if found is not None:
        return dict(found.params), dict(found.params_std)
    block = _block(real, name)
    return dict(vars(block)), {}


def beyond_sim(rows: list[Change], sim: Plant, real: Plant, real_found: dict[str, FoundEffect],
               held: dict[str, HeldOutTest], shares: dict[str, float]) -> list[FoundEffect]:
    """What the real drive has that the simulation lacks, one entry per effect (``held``:
    each effect's held-out test on the real data, ``shares``: its share of the mismatch)."""
    out = []
    for name, rs in groups(rows).items():
        if all(r.real is None for r in rs):
            continue
        best = max(rs, key=lambda r: r.significance)
        f = real_found.get(name)
        params, std = _params(name, rs, sim, real, f)
        out.append(FoundEffect(name, params, std, best.significance, shares.get(name, 0.0),
                               held.get(name), best.confidence))
    return out


def sim_only(rows: list[Change], sim_found: dict[str, FoundEffect],
             held: dict[str, HeldOutTest], shares: dict[str, float],
             sim: Plant) -> list[FoundEffect]:
    """What the simulation has that the real drive lacks, one entry per effect."""
    out = []
    for name, rs in groups(rows).items():
        if not all(r.real is None for r in rs):
            continue
        r = rs[0]
        f = sim_found.get(name)
        params = dict(f.params) if f is not None else dict(vars(_block(sim, name)))
        std = dict(f.params_std) if f is not None else {}
        out.append(FoundEffect(name, params, std, r.significance, shares.get(name, 0.0),
                               held.get(name), r.confidence))
    return out


def _num(value: float, param: str) -> str:
    _, unit, scale = PARAM_WORDS[param]
    return f"{value * scale:.3g} {unit}"


def _rigid_words(r: Change) -> str:
    assert r.sim is not None and r.real is not None
    rel = (r.real - r.sim) / r.sim if r.sim else float("inf")
    if r.param == "mass_kg":
        what = f"{abs(rel):.0%} {'heavier' if rel > 0 else 'lighter'}"
        return (f"the real axis is {what} ({r.real:.4g} ± {r.std:.2g} kg against "
                f"{r.sim:.4g} kg)")
    if r.sim <= 0:
        return (f"the real axis has {r.real:.4g} ± {r.std:.2g} N·s/m of viscous damping the "
                "simulation lacks")
    what = f"{abs(rel):.0%} {'more' if rel > 0 else 'less'} viscous damping"
    return (f"the real axis has {what} ({r.real:.4g} ± {r.std:.2g} against {r.sim:.4g} "
            "N·s/m)")


def _size(name: str, p: Plant) -> str:
    """The effect's size in a few words, e.g. '0.8 N at a 6 mm pitch'."""
    b = _block(p, name)
    if name in ("cogging", "thrust_ripple"):
        key = "amplitude_n" if name == "cogging" else "relative"
        return f"{_num(getattr(b, key), key)} at a {_num(b.pitch_m, 'pitch_m')} pitch"
    if name == "stribeck_friction":
        return (f"{_num(b.static_n, 'static_n')} at "
                f"{_num(b.velocity_mps, 'velocity_mps')}")
    key = next(k for k in vars(b) if k in PARAM_WORDS)
    return _num(getattr(b, key), key)


def in_words(r: Change, sim: Plant, real: Plant) -> str:
    """One sentence, side by side, for people (module doc)."""
    if r.effect in RIGID_PARAMS:
        return _rigid_words(r)
    label = LABEL.get(r.effect, r.effect)
    if r.sim is None:
        article = "" if r.effect in ("coulomb_friction", "stribeck_friction") else "a "
        return (f"the real axis has {article}{label} of {_size(r.effect, real)} the "
                "simulation lacks")
    if r.real is None:
        return f"the simulation has a {label} ({_size(r.effect, sim)}) the real axis does not show"
    words = PARAM_WORDS[r.param][0]
    if r.param == "phase_rad":
        return (f"the real axis's {label} sits at another phase ({r.real:.3g} against "
                f"{r.sim:.3g} rad)")
    more = "larger" if r.real > r.sim else "smaller"
    if r.param in ("amplitude_n", "static_n"):
        more = "stronger" if abs(r.real) > abs(r.sim) else "weaker"
    return (f"the real axis's {label} {words} is {more}: {_num(r.real, r.param)} ± "
            f"{_num(r.std, r.param)} against {_num(r.sim, r.param)}")


__all__ = ["SimComparison", "apply_changes", "beyond_sim", "groups", "in_words", "sim_only"]
