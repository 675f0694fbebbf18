"""The columns of the fleet table and one recording's row, from the fit-plant and diagnose
results (their JSON dictionaries).

One row per recording (per axis of a recording): what it is (``recording``, ``axis``,
``start_time``, ``duration_s``, ``sample_rate_hz``), whether it was analysed (``status``
``ok`` or ``error``, and ``error``, the one-line reason), the fitted physical plant
(``mass_kg``, ``viscous_n_per_mps`` and, for every parameter of every effect of the library,
``<effect>.<param>``; each with ``.std``, its standard error; empty where the effect was not
found), ``<effect>.confidence``, and the fit of the reference plant before and after the
diagnosed corrections (``nrmse_before``, ``nrmse_after``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

#: Parameters of each effect of the library, in the order of the plant file (SI units).
#: ``cogging.harmonics`` is a list of ``{order, amplitude_n, phase_rad}``; the rest are numbers.
EFFECT_PARAMS: dict[str, tuple[str, ...]] = {
    "cogging": ("amplitude_n", "pitch_m", "phase_rad", "harmonics"),
    "coulomb_friction": ("amplitude_n",),
    "stribeck_friction": ("static_n", "velocity_mps"),
    "force_offset": ("amplitude_n",),
    "thrust_ripple": ("relative", "pitch_m", "phase_rad"),
    "thrust_lag": ("tau_s",),
    "transport_delay": ("delay_s",),
    "spring": ("stiffness_n_per_m",),
}

#: The parameter of each effect that is zero when the effect is absent (its size): a trend
#: compares it whether or not the effect was found, so an effect that appears is a change.
MAGNITUDE: dict[str, str] = {
    "cogging": "amplitude_n", "coulomb_friction": "amplitude_n",
    "stribeck_friction": "static_n", "force_offset": "amplitude_n",
    "thrust_ripple": "relative", "thrust_lag": "tau_s", "transport_delay": "delay_s",
    "spring": "stiffness_n_per_m",
}

#: Parameters never trended: an angle wraps and depends on where the scale's zero is.
NOT_TRENDED = ("phase_rad", "harmonics")

#: Columns every row has, in order, before the plant's.
HEAD = ("recording", "axis", "start_time", "duration_s", "sample_rate_hz", "status", "error")
#: The rigid-body parameters of the plant.
RIGID = ("mass_kg", "viscous_n_per_mps")
#: Columns after the plant's: the fit of the reference plant before/after, then bookkeeping.
TAIL = ("nrmse_before", "nrmse_after", "effects", "diagnosed", "samples", "speed_derived",
        "namespace", "joint", "content_sha256", "analysed_at", "elapsed_s")


def param_columns() -> list[str]:
    """``mass_kg``, ``viscous_n_per_mps`` and every ``<effect>.<param>``, each followed by its
    ``.std``, then ``<effect>.confidence`` per effect."""
    cols: list[str] = []
    for name in RIGID:
        cols += [name, name + ".std"]
    for effect, params in EFFECT_PARAMS.items():
        for p in params:
            cols += [f"{effect}.{p}", f"{effect}.{p}.std"]
        cols.append(f"{effect}.confidence")
    return cols


def columns() -> list[str]:
    """Every column of the fleet table, in order."""
    return [*HEAD, *param_columns(), *TAIL]


def trended_parameters() -> list[str]:
    """The parameters whose trend is followed per axis (numbers; phases are not)."""
    out = list(RIGID)
    for effect, params in EFFECT_PARAMS.items():
        out += [f"{effect}.{p}" for p in params if p not in NOT_TRENDED]
    return out


def magnitude_of(parameter: str) -> bool:
    """Whether ``parameter`` is zero when its effect is absent (rigid parameters: never)."""
    effect, _, param = parameter.partition(".")
    return MAGNITUDE.get(effect) == param


def _number(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def _harmonics(values: Any) -> list[dict[str, Any]] | None:
    if not isinstance(values, Sequence) or isinstance(values, str):
        return None
    out = []
    for h in values:
        if isinstance(h, Mapping) and "order" in h:
            out.append({"order": int(h["order"]), "amplitude_n": _number(h.get("amplitude_n")),
                        "phase_rad": _number(h.get("phase_rad"))})
    return out


def _harmonic_std(std: Mapping[str, Any], orders: list[int]) -> list[dict[str, Any]] | None:
    """Standard errors of the harmonics: a list like the values', or diagnose's
    ``harmonic_<order>_amplitude_n`` keys."""
    listed = _harmonics(std.get("harmonics"))
    if listed is not None:
        return listed
    return [{"order": h, "amplitude_n": _number(std.get(f"harmonic_{h}_amplitude_n")),
             "phase_rad": None} for h in orders]


def plant_columns(plant: Mapping[str, Any], std: Mapping[str, Any],
                  effects: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The plant part of a row: a fitted plant dict (plant-file keys), its standard errors
    (same keys and nesting) and the found effects (for their confidence)."""
    row: dict[str, Any] = dict.fromkeys(param_columns())
    for name in RIGID:
        row[name] = _number(plant.get(name))
        row[name + ".std"] = _number(std.get(name))
    confidence = {str(e.get("name")): e.get("confidence") for e in effects}
    for effect, params in EFFECT_PARAMS.items():
        block = plant.get(effect)
        if not isinstance(block, Mapping):
            continue
        sd = std.get(effect)
        sd = sd if isinstance(sd, Mapping) else {}
        for p in params:
            if p == "harmonics":
                values = _harmonics(block.get(p)) or []
                row[f"{effect}.{p}"] = values
                row[f"{effect}.{p}.std"] = _harmonic_std(sd, [h["order"] for h in values])
            else:
                row[f"{effect}.{p}"] = _number(block.get(p))
                row[f"{effect}.{p}.std"] = _number(sd.get(p))
        c = confidence.get(effect)
        row[f"{effect}.confidence"] = str(c) if c is not None else None
    return row


def diagnosis_columns(diagnosis: Mapping[str, Any]) -> dict[str, Any]:
    """``nrmse_before``/``nrmse_after`` (the force equation error of the reference plant
    before and after the diagnosed corrections, on the held-out part) and ``diagnosed`` (the
    names of the effects the reference plant lacks)."""
    fit = diagnosis.get("fit")
    fit = fit if isinstance(fit, Mapping) else {}
    seg = fit.get("validation") or fit.get("estimation") or {}
    return {"nrmse_before": _number(seg.get("nrmse_before")),
            "nrmse_after": _number(seg.get("nrmse_after")),
            "diagnosed": [str(e.get("name")) for e in diagnosis.get("effects") or []]}


def empty_row() -> dict[str, Any]:
    """A row with every column empty."""
    return dict.fromkeys(columns())
