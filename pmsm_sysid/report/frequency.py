"""Report sections in the frequency domain (Section V of Liu et al. 2005): H1, H2 and H3 with the
peaks and ridges of the gfrf JSON (the same analysis as ``pmsm-sysid gfrf``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .. import plots
from ..core.errors import PmsmSysidError
from ..core.frequency.gfrf import Gfrf
from ..core.terms.model import NarxModel
from .html import Block, Facts, Note, Section, Table
from .sink import Sink

H1_POINTS = 2049
H2_GRID = 256
H3_GRID = 160
N_FREQ_FIGURES = 4


def _yes(v: Any) -> str:
    return {True: "yes", False: "no", None: "unchecked"}.get(v, str(v))


def peak_table(g: Mapping[str, Any]) -> Table:
    fs = float(g["sample_rate_hz"])
    rows = tuple((str(p["kind"]), f"{p['freq_norm']:.4f}", f"{p['freq_norm'] * fs:.2f}",
                  f"{p['gain_db']:.2f}", f"{p.get('phase_deg', float('nan')):.1f}",
                  _yes(p.get("supported"))) for p in g["h1"]["peaks"])
    return Table("H1 peaks", ("kind", "f (cycles/sample)", "f (Hz)", "gain (dB)",
                              "phase (deg)", "supported"), rows)


def ridge_table(g: Mapping[str, Any], order: str) -> Table:
    fs = float(g["sample_rate_hz"])
    rows = tuple((str(r["kind"]), f"±{r['freq_norm']:.4f}", f"±{r['freq_norm'] * fs:.2f}",
                  f"{r['level_db']:.2f}", _yes(r.get("dominant")), _yes(r.get("supported")))
                 for r in g[order]["ridges"] if int(r.get("sign", 1)) > 0)
    where = " on the slice f1 = f3" if order == "h3" else ""
    return Table(f"{order.upper()} ridges{where} (line kind = ±f0)",
                 ("kind", "f0 (cycles/sample)", "f0 (Hz)", "level (dB)", "dominant",
                  "supported"), rows)


def _view(g: Mapping[str, Any], model_json: Mapping[str, Any] | None) -> float:
    """Half-width of the H2/H3 views: the dominant ridges, the top H1 peak, the tones."""
    freqs = [float(r["freq_norm"]) for r in g["h2"]["ridges"] if r.get("dominant")]
    freqs += [float(p["freq_norm"]) for p in g["h1"]["peaks"][:1]]
    ex = (model_json or {}).get("excitation") or {}
    fs = float(g["sample_rate_hz"])
    freqs += [float(t) / fs for t in ex.get("tones_hz") or []]
    return plots.view_fmax(freqs)


def _ratio(input_name: str, output_name: str) -> str:
    """The unit of |H1| from input to output, e.g. ``(m/s)/N``; '' when one is unknown."""
    from ..plots.signals import UNITS

    u, y = UNITS.get(input_name), UNITS.get(output_name)
    if not (u and y):
        return ""
    return f"{f'({y})' if '/' in y else y}/{u}"


def _excited(model_json: Mapping[str, Any] | None) -> list[tuple[float, float]] | None:
    """Where the estimation input has power (cycles/sample), when the JSON says: a narrow
    band around each tone of a tonal input (the stretch between tones holds no power), the
    band of most of the input's power otherwise."""
    from ..core.selection.identifiability import ExcitationSummary, tone_tolerance_hz

    ex = (model_json or {}).get("excitation")
    if not ex:
        return None
    try:
        s = ExcitationSummary.from_dict(ex)
    except PmsmSysidError:
        return None
    fs = s.sample_rate_hz
    if s.tonal and s.tones_hz:
        return [(max(t - tone_tolerance_hz(s, t), 0.0) / fs,
                 min(t + tone_tolerance_hz(s, t), fs / 2) / fs) for t in s.tones_hz]
    return [s.band_norm]


def gfrf_facts(g: Mapping[str, Any]) -> Facts:
    return Facts((
        ("linear part", f"{'stable' if g['stable'] else 'UNSTABLE'}, "
                        f"{len(g['poles'])} pole{'' if len(g['poles']) == 1 else 's'}, "
                        f"largest radius {float(g.get('max_pole_radius', 0.0)):.4f}"),
        ("identifiability", str((g.get("identifiability") or {}).get("rests_on", "n/a"))),
    ))


def tables(g: Mapping[str, Any]) -> list[Block]:
    blocks: list[Block] = [gfrf_facts(g)]
    blocks += [Note(str(w)) for w in (*g.get("warnings", []), *g.get("notes", []))]
    blocks.append(peak_table(g))
    for order in ("h2", "h3"):
        if g[order].get("ridges"):
            blocks.append(ridge_table(g, order))
        if g[order].get("note"):
            blocks.append(Note(f"{order.upper()}: {g[order]['note']}"))
    return blocks


def model_sections(model: NarxModel, g: Mapping[str, Any], sink: Sink,
                   model_json: Mapping[str, Any] | None = None) -> list[Section]:
    """H1, H2 (contour and surface) and the H3 slice of ``model``; ridges from ``g``."""
    gf = Gfrf.from_model(model)
    fs = float(g["sample_rate_hz"])
    fmax = _view(g, model_json)
    f1, h1 = gf.h1_curve(H1_POINTS)
    f2, h2 = gf.h2_grid(H2_GRID, fmax)
    f3, h3 = gf.h3_slice(H3_GRID, fmax)
    title = f"{model.input_name} → {model.output_name} model"
    blocks: list[Block] = [
        sink.figure(plots.h1_gain_phase(f1, h1, fs, g["h1"]["peaks"], f"H1(f), {title}",
                                        excited=_excited(model_json),
                                        gain_unit=_ratio(model.input_name, model.output_name))),
        sink.figure(plots.h2_contour(f2, h2, fs, g["h2"]["ridges"],
                                     f"|H2(f1, f2)|, {title}")),
        sink.figure(plots.h2_surface(f2, h2, fs, g["h2"]["ridges"])),
        sink.figure(plots.h3_slice(f3, h3, fs, g["h3"]["ridges"],
                                   f"|H3(f1, f2, f1)|, {title}")),
    ]
    return [Section("Frequency domain: GFRFs (Figs. 12-17 of Liu et al. 2005)",
                    tuple(blocks + tables(g)))]


def _grid_arrays(grid: Mapping[str, Any], key: str) -> np.ndarray:
    return np.asarray(10.0 ** (np.asarray(grid[key], dtype=np.float64) / 20.0))


def json_sections(g: Mapping[str, Any], sink: Sink) -> list[Section]:
    """A gfrf JSON alone: its tables, and its ``grid`` (from ``gfrf --grid N``) if present."""
    fs = float(g["sample_rate_hz"])
    blocks: list[Block] = []
    grid = g.get("grid")
    if grid:
        f = np.asarray(grid["f_norm"], dtype=np.float64)
        blocks.append(sink.figure(plots.h1_gain_phase(
            grid["h1_f_norm"], _grid_arrays(grid, "h1_db"), fs, g["h1"]["peaks"],
            "H1(f): gain from the gfrf JSON grid (no phase in the JSON)", phase=False)))
        blocks.append(sink.figure(plots.h2_contour(f, _grid_arrays(grid, "h2_db"), fs,
                                                   g["h2"]["ridges"])))
        blocks.append(sink.figure(plots.h3_slice(f, _grid_arrays(grid, "h3_slice_db"), fs,
                                                 g["h3"]["ridges"])))
    else:  # said on the page and, through the notes, on the terminal
        sink.notes.append("no GFRF figures: this gfrf JSON has no 'grid' (write it with "
                          "'pmsm-sysid gfrf MODEL --grid 256 --json FILE', or report the "
                          "identify JSON instead)")
        blocks.append(Note(sink.notes[-1]))
    return [Section("Frequency domain: GFRFs (Figs. 12-17 of Liu et al. 2005)",
                    tuple(blocks + tables(g)))]

