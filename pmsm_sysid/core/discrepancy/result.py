"""The diagnosis result: found effects, where the mismatch lives, fits before/after.

``DiagnoseResult.to_dict()`` is the ``diagnose`` JSON plus extra keys
(``params_std``, ``held_out``, ``confidence``, ``method`` ...); ``summary()`` is the
human report the CLI prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..physics.plant import Plant, plant_to_dict
from .locate import AxisFinding
from .stats import HeldOutTest

FloatArray = NDArray[np.float64]

SIGNIFICANCE_CAP = 300.0


@dataclass(frozen=True)
class FoundEffect:
    """One named effect (or ``unexplained``) with parameters, uncertainty and confidence."""

    name: str
    params: dict[str, Any]
    params_std: dict[str, float]
    significance: float
    explains: float
    held_out: HeldOutTest | None = None
    confidence: str = "moderate"
    notes: tuple[str, ...] = ()
    alternative: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name, "params": self.params, "significance": self.significance,
            "explains": self.explains, "params_std": self.params_std,
            "p_value": 10.0 ** -min(self.significance, SIGNIFICANCE_CAP),
            "confidence": self.confidence}
        if self.held_out is not None:
            h = self.held_out
            out["held_out"] = {"reduction": h.reduction, "z": h.z, "p_value": h.p_value,
                               "confirmed": h.confirmed, "significant": h.significant}
        if self.alternative is not None:
            out["alternative"] = self.alternative
        if self.notes:
            out["notes"] = list(self.notes)
        return out


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

    def to_dict(self) -> dict[str, Any]:
        return {
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
        lines = [f"equation-error NRMSE of the nominal plant: {self.nrmse_before:.4f}"]
        named = [e for e in self.effects if e.name != "unexplained"]
        if not named:
            lines.append("no significant missing physics"
                         + (" in the library" if self.effects else ""))
        for e in self.effects:
            lines.append(_effect_line(e))
            lines += [f"    note: {n}" for n in e.notes]
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
        strong = [w for w in self.where if w.significance >= 3.0]
        if strong and self.effects:
            lines.append("mismatch lives over: " + ", ".join(
                f"{w.axis} ({w.share:.0%})" for w in sorted(strong, key=lambda w: -w.share)))
        if self.gfrf is not None:
            st = self.gfrf.get("structure") or {}
            what = (f"NARX ny={st['ny']} nu={st['nu']} degree {st['degree']}, "
                    if st else "")
            lines.append(f"GFRF ({what}real data vs noisy twin): {self.gfrf['note']}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _fmt(value: Any, std: float | None) -> str:
    if isinstance(value, float):
        if std is not None and math.isfinite(std):
            return f"{value:.5g} ± {std:.2g}"
        return f"{value:.5g}"
    if isinstance(value, list):
        return "[" + ", ".join(
            "h{order}: {amp:.3g} N".format(order=h["order"], amp=h["amplitude_n"])
            if isinstance(h, dict) and "order" in h
            else f"{h:.5g}" if isinstance(h, float) else str(h) for h in value) + "]"
    return str(value)


def _effect_line(e: FoundEffect) -> str:
    keys = [k for k in e.params
            if not k.endswith("_means_n") and k not in ("window_rms_n", "curve")]
    params = ", ".join(f"{k}={_fmt(e.params[k], e.params_std.get(k))}" for k in keys)
    sig = f">{SIGNIFICANCE_CAP:.0f}" if e.significance >= SIGNIFICANCE_CAP \
        else f"{e.significance:.1f}"
    held = ""
    if e.held_out is not None:
        held = f", held-out MSE -{e.held_out.reduction:.0%} (z={e.held_out.z:.1f})"
    alt = ""
    if e.alternative is not None:
        alt = f"; vs {e.alternative['name']}: Δχ²={e.alternative['delta_chi2']:.1f}"
    return (f"  {e.name}: {params}  [significance {sig}, explains {e.explains:.1%}"
            f"{held}, confidence {e.confidence}{alt}]")


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


def capped(log10_p: float) -> float:
    """-log10 p, capped for JSON (p underflows long before real evidence runs out)."""
    if not np.isfinite(log10_p):
        return SIGNIFICANCE_CAP
    return float(min(SIGNIFICANCE_CAP, max(0.0, -log10_p)))
