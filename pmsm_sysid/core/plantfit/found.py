"""A named effect found in a recording: parameters, uncertainty, significance, confidence.

Shared by the plant fitted from a recording (:mod:`.fit`) and by ``diagnose``, which reports
the effects a reference plant leaves out in the same shape.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .stats import HeldOutTest

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
    profile: dict[str, Any] | None = None
    """Stribeck friction: the fit over its velocity (:mod:`.profile`)."""

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
        if self.profile is not None:
            out["profile"] = self.profile
        if self.notes:
            out["notes"] = list(self.notes)
        return out


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


def effect_line(e: FoundEffect, described: str | None = None) -> str:
    """One line for people: the parameters with their errors (or ``described``, the effect
    in words), the evidence, the confidence."""
    keys = [k for k in e.params
            if not k.endswith("_means_n") and k not in ("window_rms_n", "curve")]
    params = described or ", ".join(f"{k}={_fmt(e.params[k], e.params_std.get(k))}"
                                    for k in keys)
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


def capped(log10_p: float) -> float:
    """-log10 p, capped for JSON (p underflows long before real evidence runs out)."""
    if not np.isfinite(log10_p):
        return SIGNIFICANCE_CAP
    return float(min(SIGNIFICANCE_CAP, max(0.0, -log10_p)))
