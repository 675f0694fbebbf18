"""Reading a live diagnosis (the diagnose JSON of one span): its numbers and its words.

The diagnosis node publishes, per span, the diagnose JSON with a ``window`` block; the node's
plottable numbers, its health, the monitor, the run summary and the run report all read it
through these functions, so they say the same thing:

* :data:`EFFECT_NUMBERS`: per library effect, the parameters published as numbers (with
  their units; the first is the effect's headline number);
* :func:`numbers`: every such number of one diagnosis (NaN for an effect not named), the
  count of named and of unexplained effects, and the held-out force NRMSE before and after;
* :func:`effect_text` / :func:`found_text`: "coulomb_friction 2.01 N (high)" and the like.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from .clocktext import stamp_text
from .topics import DIAGNOSIS_PARAMS

#: effect -> (param, unit) published per diagnosis; the first is the headline number
EFFECT_NUMBERS = DIAGNOSIS_PARAMS
UNEXPLAINED = "unexplained"


def _float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def effects(d: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """Every effect of a diagnosis (named ones and ``unexplained`` mismatches)."""
    return [e for e in d.get("effects") or [] if isinstance(e, Mapping)]


def sim_only(d: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """Against a simulator's recording: the effects the simulation has and the drive lacks."""
    return [e for e in d.get("sim_only") or [] if isinstance(e, Mapping)]


def mismatch(d: Mapping[str, Any]) -> bool:
    """The diagnosis found a difference: physics the reference lacks (or, against a
    simulator's recording, physics only the simulation has)."""
    return bool(effects(d) or sim_only(d))


def named(d: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """The library effects a diagnosis named."""
    return [e for e in effects(d) if e.get("name") != UNEXPLAINED]


def held_out_nrmse(d: Mapping[str, Any]) -> tuple[float, float]:
    """Force NRMSE (equation error) on the held-out data, before and after the effects."""
    fit = (d.get("fit") or {}).get("validation") or {}
    return _float(fit.get("nrmse_before")), _float(fit.get("nrmse_after"))


def numbers(d: Mapping[str, Any]) -> dict[str, float]:
    """``<effect>/<param>`` -> value for every effect of :data:`EFFECT_NUMBERS` (NaN when
    not named), plus ``effects_named``, ``unexplained``, ``force_nrmse_before|after``."""
    found = {str(e.get("name")): e.get("params") or {} for e in named(d)}
    out = {f"{name}/{param}": _float(found[name].get(param)) if name in found else math.nan
           for name, params in EFFECT_NUMBERS.items() for param, _ in params}
    before, after = held_out_nrmse(d)
    out.update(effects_named=float(len(found)),
               unexplained=float(len(effects(d)) - len(named(d))),
               force_nrmse_before=before, force_nrmse_after=after)
    return out


def value_text(value: Any, unit: str) -> str:
    """3 significant digits and the unit (mm and ms below 0.1 m and 0.1 s)."""
    x = _float(value)
    if not math.isfinite(x):
        return "-"
    if unit in ("m", "s") and abs(x) < 0.1:
        x, unit = x * 1e3, "m" + unit
    text = f"{x:.3g}"
    return text if unit == "1" else f"{text} {unit}"


def effect_text(e: Mapping[str, Any], confidence: bool = True) -> str:
    """``coulomb_friction 2.01 N (high)``; a cogging or ripple with its pitch; an
    unexplained mismatch with the axis it lives on."""
    name = str(e.get("name"))
    params = e.get("params") or {}
    if name == UNEXPLAINED:
        text = f"{name} ({params.get('axis', '?')})"
    else:
        spec = EFFECT_NUMBERS.get(name, ())
        text = name
        if spec:
            text += " " + value_text(params.get(spec[0][0]), spec[0][1])
        if name in ("cogging", "thrust_ripple"):
            text += " at " + value_text(params.get("pitch_m"), "m")
    if confidence and e.get("confidence"):
        text += f" ({e['confidence']})"
    return text


def found_text(d: Mapping[str, Any], limit: int | None = None,
               confidence: bool = True) -> str:
    """What a diagnosis found, in a few words: the effects, or "nothing missing" (and what
    only the simulation has, against a simulator's recording)."""
    found: Sequence[Mapping[str, Any]] = effects(d)
    shown = [effect_text(e, confidence) for e in found[:limit]]
    more = len(found) - len(shown)
    text = (", ".join(shown) + (f" +{more}" if more > 0 else "")) if found \
        else "nothing missing"
    extra = sim_only(d)
    if extra:
        text += "; only in the simulation: " + ", ".join(effect_text(e, confidence)
                                                          for e in extra)
    return text


def line(d: Mapping[str, Any]) -> str:
    """One line for the log: the span, what was found, the held-out fit before and after."""
    w = d.get("window") or {}
    fs = _float(w.get("sample_rate_hz"))
    span = _float(w.get("samples")) / fs if fs > 0 else math.nan
    before, after = held_out_nrmse(d)
    fit = (f"; held-out force NRMSE {before:.3g} -> {after:.3g}" if effects(d)
           else f"; held-out force NRMSE {before:.3g}")
    end = stamp_text(_float(w.get("end_stamp")), prefix="t=")
    return (f"diagnosis of {span:.3g} s ending at {end}: "
            f"{found_text(d)}{fit}")


class DiagnosisHistory:
    """One row per diagnosis (span end ``t``, the numbers of :func:`numbers` that are not
    NaN, the effects' names), for the run report. Beyond ``max_rows`` every other row is
    dropped (``stride`` then says how many diagnoses one row stands for), so an hour-long
    run keeps a picture of the whole hour in bounded memory."""

    def __init__(self, max_rows: int = 2048) -> None:
        if max_rows < 8:
            raise ValueError(f"max_rows must be >= 8, got {max_rows}")
        self.max_rows = max_rows
        self.rows: list[dict[str, Any]] = []
        self.stride = 1
        self.seen = 0

    def add(self, d: Mapping[str, Any]) -> None:
        self.seen += 1
        if (self.seen - 1) % self.stride:
            return
        w = d.get("window") or {}
        values = {k: v for k, v in numbers(d).items() if math.isfinite(v)}
        t = _float(w.get("end_stamp"))
        self.rows.append({"seq": w.get("seq"), "t": t if math.isfinite(t) else None,
                          "numbers": values, "effects": [str(e.get("name"))
                                                         for e in effects(d)]})
        if len(self.rows) > self.max_rows:
            self.rows = self.rows[::2]
            self.stride *= 2

    def to_dict(self) -> dict[str, Any]:
        return {"rows": list(self.rows), "stride": self.stride, "diagnoses": self.seen}


def run_history(col: Any) -> dict[str, Any] | None:
    """The run summary's ``history``: a result collector's window-by-window history of the
    models and its span-by-span history of the diagnoses (``diagnosis``)."""
    if col is None:
        return None
    out: dict[str, Any] = col.history.to_dict()
    out["diagnosis"] = col.diagnosis_history.to_dict()
    return out


def diagnosis_summary(node: Any, col: Any) -> dict[str, Any]:
    """The run summary's diagnosis part: ``last_diagnosis`` (the diagnose JSON of the
    latest span), ``diagnoses_run``, ``diagnoses_skipped``, ``diagnoses_failed``,
    ``diagnoses_due`` and the diagnosis node's details (``diagnose``); without the node in
    this process, the latest diagnosis the collector ``col`` saw and null counters."""
    keys = ("diagnoses_due", "diagnoses_run", "diagnoses_skipped", "diagnoses_failed")
    if node is None:
        return {"last_diagnosis": col.last_diagnosis if col is not None else None,
                **dict.fromkeys(keys)}
    details = node.summary()
    out = {"last_diagnosis": details.pop("last_diagnosis"),
           **{k: details.pop(k) for k in keys}}
    out["diagnose"] = details
    return out
