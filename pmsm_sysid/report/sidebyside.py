"""Report section of a diagnosis against a simulator's recording (``diagnose --sim``): the
simulation's plant and the real drive's side by side, the changes in words and as a table,
and what the simulation has that the real drive lacks."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from .html import Block, Note, Section, Table

RIGID = ("mass_kg", "viscous_n_per_mps")


def _num(value: Any, std: Any = None) -> str:
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return "—" if value is None else str(value)
    if isinstance(std, (int, float)) and math.isfinite(std):
        return f"{value:.5g} ± {std:.2g}"
    return f"{value:.5g}"


def _flat(plant: Mapping[str, Any]) -> dict[str, tuple[Any, Any]]:
    """``<effect>.<param>`` -> (value, std) of a fitted plant dict with its ``std``."""
    std = plant.get("std") or {}
    out: dict[str, tuple[Any, Any]] = {k: (plant.get(k), std.get(k)) for k in RIGID}
    for name, block in plant.items():
        if not isinstance(block, Mapping) or name in ("std", "noise", "quantisation"):
            continue
        sd = std.get(name) or {}
        for key, value in block.items():
            if key != "smoothing_mps" and isinstance(value, (int, float)):
                out[f"{name}.{key}"] = (value, sd.get(key))
    return out


def plants_table(d: Mapping[str, Any]) -> Table:
    """Every parameter of either fitted plant, simulation beside real drive."""
    sim, real = _flat(d.get("sim_plant") or {}), _flat(d.get("real_plant") or {})
    rows = tuple((k, _num(*sim.get(k, (None, None))), _num(*real.get(k, (None, None))))
                 for k in dict.fromkeys([*sim, *real]))
    return Table("The plants fitted from the two recordings (± standard error; — where a "
                 "plant has no such effect)", ("parameter", "simulation", "real drive"), rows)


def changes_table(d: Mapping[str, Any]) -> Table:
    """One row per parameter that differs significantly against both fits' errors."""
    rows = tuple((str(c.get("parameter")), _num(c.get("sim")), _num(c.get("real")),
                  _num(c.get("std")), _num(c.get("significance")), str(c.get("confidence")))
                 for c in d.get("changes") or [])
    return Table("Changes (significance = -log10 of the Bonferroni-corrected p-value of the "
                 "difference against the combined standard error)",
                 ("parameter", "simulation", "real drive", "± std", "significance",
                  "confidence"), rows)


def sim_sections(d: Mapping[str, Any]) -> list[Section]:
    """The side-by-side section, first on the page (nothing for a plant-file diagnosis)."""
    if d.get("reference") != "sim_recording":
        return []
    words = [str(w) for w in d.get("side_by_side") or []]
    blocks: list[Block] = [Note(w) for w in words] or [Note(
        "no significant difference: the real drive's plant matches the simulation's within "
        "their combined errors")]
    blocks += [plants_table(d)]
    if d.get("changes"):
        blocks.append(changes_table(d))
    only = d.get("sim_only") or []
    if only:
        blocks.append(Table("What the simulation has that the real drive lacks",
                            ("effect", "significance", "confidence"),
                            tuple((str(e.get("name")), _num(e.get("significance")),
                                   str(e.get("confidence"))) for e in only)))
    return [Section("The simulation against the real drive, side by side", tuple(blocks))]
