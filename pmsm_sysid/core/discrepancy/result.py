"""The diagnosis result: found effects, where the mismatch lives, fits before/after.

``DiagnoseResult.to_dict()`` is the ``diagnose`` JSON plus extra keys
(``params_std``, ``held_out``, ``confidence``, ``method`` ...); ``summary()`` is the
human report the CLI prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..physics.plant import Plant, plant_to_dict
from ..plantfit.found import FoundEffect, effect_line
from .locate import AxisFinding
from .words import unexplained_text, used_lines, where_text

if TYPE_CHECKING:
    from .sidebyside import SimComparison

FloatArray = NDArray[np.float64]

@dataclass(frozen=True)
class Curves:
    """Series for figures (not part of the JSON): one entry per data segment."""

    t: dict[str, FloatArray] = field(default_factory=dict)
    x: dict[str, FloatArray] = field(default_factory=dict)
    v: dict[str, FloatArray] = field(default_factory=dict)
    before: dict[str, FloatArray] = field(default_factory=dict)
    after: dict[str, FloatArray] = field(default_factory=dict)
    parts: dict[str, list[tuple[str, FloatArray]]] = field(default_factory=dict)
    replay: dict[str, dict[str, FloatArray]] = field(default_factory=dict)


@dataclass(frozen=True)
class DiagnoseResult:
    """Everything ``diagnose`` found; ``to_dict`` is the JSON."""

    plant: Plant
    corrected: Plant
    effects: tuple[FoundEffect, ...]
    where: tuple[AxisFinding, ...]
    nrmse_before: float
    fit: dict[str, Any]
    candidates: tuple[dict[str, Any], ...]
    method: dict[str, Any]
    notes: tuple[str, ...] = ()
    curves: Curves = field(default_factory=Curves)
    gfrf: dict[str, Any] | None = None  # the GFRF comparison's mismatch.where entry
    against: SimComparison | None = None
    """Set when the reference is a simulator's recording (its fitted plant is ``plant``)."""

    def to_dict(self) -> dict[str, Any]:
        extra = self.against.to_dict() if self.against is not None \
            else {"reference": "plant_file"}
        return {**extra,
            "plant": plant_to_dict(self.plant),
            "mismatch": {"nrmse_before": self.nrmse_before,
                         "where": [w.to_dict() for w in self.where]
                         + ([self.gfrf] if self.gfrf is not None else []),
                         "candidates": list(self.candidates)},
            "effects": [e.to_dict() for e in self.effects],
            "corrected_plant": plant_to_dict(self.corrected),
            "fit": self.fit,
            "method": self.method,
            "notes": list(self.notes),
        }

    def summary(self) -> str:
        """A few lines for people: found effects, fit before/after, where it lived."""
        what = "the nominal plant" if self.against is None else "the simulation's plant"
        lines = self.against.summary_lines() if self.against is not None else []
        lines.append(f"equation-error NRMSE of {what}: {self.nrmse_before:.4f}")
        lines += used_lines(self.method)
        named = [e for e in self.effects if e.name != "unexplained"]
        if not named:
            lines.append("no significant missing physics"
                         + (" in the library" if self.effects else ""))
        elif self.against is not None:
            lines.append("what the real drive has beyond the simulation:")
        for e in self.effects:  # an unexplained force in words, where it acts
            lines.append(effect_line(e, unexplained_text(e.params)
                                     if e.name == "unexplained" else None))
            lines += [f"    note: {n}" for n in e.notes]
        if self.against is not None and self.against.sim_only:
            lines.append("what the simulation has that the real drive lacks:")
            lines += [effect_line(e) for e in self.against.sim_only]
        for seg in ("estimation", "validation"):
            f = self.fit.get(seg)
            if f:
                lines.append(_fit_line(seg, f))
        tests = (self.fit.get("estimation") or {}).get("correlation_tests")
        if tests:
            fails = {k: [n for n, t in v.items() if not t["pass"]] for k, v in tests.items()}
            lines.append("correlation tests (Eq. 13 of Liu et al. 2005, prewhitened "
                         "residual) failing: "
                         f"before {', '.join(fails['before']) or 'none'}; "
                         f"after {', '.join(fails['after']) or 'none'}")
        lives = where_text(self.where)
        if lives and self.effects:
            lines.append(f"mismatch lives over: {lives} (each axis: what it explains beyond "
                         "the ones before it)")
        if self.gfrf is not None:
            st = self.gfrf.get("structure") or {}
            what = (f"NARX ny={st['ny']} nu={st['nu']} degree {st['degree']}, "
                    if st else "")
            lines.append(f"GFRF ({what}real data vs noisy twin): {self.gfrf['note']}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _fit_line(seg: str, f: dict[str, Any]) -> str:
    text = (f"{seg}: force NRMSE {f['nrmse_before']:.4f} -> {f['nrmse_after']:.4f}")
    oe = f.get("output_error")
    if oe:
        text += (f"; speed replay NRMSE ({oe['horizon_s']:.3g} s horizons) "
                 f"{oe['nrmse_before']:.4f} -> {oe['nrmse_after']:.4f}")
        verdict = oe.get("verdict")
        if verdict and verdict != "same":
            z = oe.get("z")
            text += f" ({verdict}" + (f", z={z:.1f})" if z is not None else ")")
    return text
