"""Report sections of a sim-to-real diagnosis (the ``diagnose`` JSON): where the mismatch
lives, the named effects with their parameters, the corrected plant and the fit table
before/after (:func:`json_sections`, also used by ``diagnose --report``), and one section per
named effect with its parameters, confidence, evidence and before/after figure
(:func:`effect_sections`).

The figures need the diagnosis' series, which the JSON does not carry: :func:`rerun` repeats
the diagnosis from the JSON's nominal plant, recordings (``real``, ``validate``) and
thresholds, checks it reproduces the JSON, and :mod:`pmsm_sysid.plots.diagnose` draws it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..core.discrepancy.words import significance_text, unexplained_text
from ..core.errors import PmsmSysidError
from .html import Block, Facts, Image, Note, Section, Table

UNITS = (("_n_per_mps", "N·s/m"), ("_n_per_m", "N/m"), ("_mps", "m/s"), ("_kg", "kg"),
         ("_rad", "rad"), ("_n", "N"), ("_m", "m"), ("_s", "s"))
HIDDEN = ("_means_n", "window_rms_n", "curve")


def _v(x: Any) -> str:
    if isinstance(x, bool) or x is None:
        return {True: "yes", False: "no", None: "n/a"}[x]
    if isinstance(x, float):
        return f"{x:.5g}"
    if isinstance(x, list):
        return "; ".join(_v(i) for i in x)
    if isinstance(x, dict):
        return ", ".join(f"{k}={_v(v)}" for k, v in x.items())
    return str(x)


def _plant(p: Mapping[str, Any]) -> Facts:
    """A plant's keys; each effect block (a mapping) as its own rows, ``effect.key``."""
    rows: list[tuple[str, str]] = []
    for k, v in p.items():
        if isinstance(v, dict):
            rows += [(f"{k}.{sub}", _param(sub, x, None)[1]) for sub, x in v.items()]
        else:
            rows.append((str(k), _param(str(k), v, None)[1]))
    return Facts(tuple(rows))


def _added(nominal: Mapping[str, Any], corrected: Mapping[str, Any]) -> list[str]:
    return [k for k, v in corrected.items() if isinstance(v, dict) and nominal.get(k) != v]


def corrected_section(d: Mapping[str, Any]) -> Section:
    """The corrected plant: the nominal (or the simulation's fitted) plant with the effects
    found, their rows first."""
    nominal, corrected = d.get("plant") or {}, d.get("corrected_plant") or {}
    added = _added(nominal, corrected)
    base = ("the simulation's plant" if d.get("reference") == "sim_recording"
            else "the nominal plant")
    what = ", ".join(f"{k} {'changed' if k in nominal else 'added'}" for k in added)
    note = (f"{base} with {what} (write it as a plant file with diagnose --corrected-plant "
            "FILE)" if added else f"no effect added: the corrected plant is {base}")
    ordered = {**{k: corrected[k] for k in added}, **{k: v for k, v in corrected.items()
                                                       if k not in added}}
    return Section("Corrected plant", (Note(note), _plant(ordered)))


def _params_text(e: Mapping[str, Any]) -> str:
    params = e.get("params") or {}
    if e.get("name") == "unexplained":
        return unexplained_text(params)
    return _v({k: v for k, v in params.items() if not k.endswith(HIDDEN)})


def effects_table(d: Mapping[str, Any]) -> Table:
    rows = tuple((str(e["name"]), _params_text(e), significance_text(e.get("significance")),
                  f"{100 * float(e.get('explains') or 0):.1f}%",
                  str(e.get("confidence", "n/a"))) for e in d.get("effects") or [])
    return Table("Named effects (significance = -log10 p; explains = share of the mismatch)",
                 ("effect", "parameters", "significance", "explains", "confidence"), rows)


def fit_table(d: Mapping[str, Any]) -> Table:
    rows = []
    for seg in ("estimation", "validation"):
        f = (d.get("fit") or {}).get(seg)
        if not f:
            continue
        oe = f.get("output_error") or {}
        rows.append((seg, _v(f.get("nrmse_before")), _v(f.get("nrmse_after")),
                     _v(oe.get("nrmse_before")), _v(oe.get("nrmse_after"))))
    return Table("Fit before/after: force (equation error) and speed replay (output error) "
                 "NRMSE", ("data", "force before", "force after", "speed before",
                           "speed after"), tuple(rows))


def _share(x: Any, sign: str = "") -> str:
    return "n/a" if x is None else f"{sign}{100 * float(x):.1f}%"


def _where_row(w: Mapping[str, Any]) -> tuple[str, str, str, str]:
    """One row of the 'where' table; entries without a share (the GFRF comparison) say n/a.
    A significance the JSON holds as null is one whose p underflowed (> 300)."""
    axis = str(w.get("axis")) + (f" ({w['source']})" if w.get("source") else "")
    sig = w.get("significance")
    if sig is None and w.get("share") is not None:
        sig = math.inf
    return (axis, _share(w.get("added_share"), "+") if "added_share" in w else "n/a",
            _share(w.get("share")), significance_text(sig))


def where_table(d: Mapping[str, Any]) -> Table:
    where = list((d.get("mismatch") or {}).get("where") or [])
    where.sort(key=lambda w: -float(w.get("added_share", -1.0)))
    return Table("Where the nominal plant's residual lives: each axis adds what it explains "
                 "beyond the axes above it (these add up to at most 100 %); alone, the axes "
                 "overlap (a force over speed shows over time too) and do not add up",
                 ("axis", "adds", "alone", "significance (-log10 p)"),
                 tuple(_where_row(w) for w in where))


def json_sections(d: Mapping[str, Any]) -> list[Section]:
    mism = d.get("mismatch") or {}
    used = [(f"data used{'' if k == 'recording' else ' (held-out recording)'}", u["text"])
            for k, u in ((d.get("method") or {}).get("data_used") or {}).items()
            if not u.get("whole", True)]
    summary: list[Block] = [Facts((("NRMSE before", _v(mism.get("nrmse_before"))),
                                   ("effects found", str(len(d.get("effects") or []))),
                                   *used)),
                            where_table(d)]
    if not d.get("effects"):
        summary.append(Note("no significant missing physics"))
    found: list[Block] = [effects_table(d), fit_table(d)]
    found += [Note(str(n)) for n in d.get("notes") or []]
    plants: list[Block] = [_plant(d.get("plant") or {})]
    from .sidebyside import sim_sections

    fitted = d.get("reference") == "sim_recording"
    return [*sim_sections(d), Section("Sim-to-real: where the mismatch lives", tuple(summary)),
            Section("Sim-to-real: named effects and fit", tuple(found)),
            Section("Simulation's plant (fitted from its recording)" if fitted
                    else "Nominal plant", tuple(plants)),
            corrected_section(d)]


def _find(name: Any, json_path: Path) -> Path | None:
    if not name:
        return None
    p = Path(str(name))
    for cand in (p,) if p.is_absolute() else (p, json_path.parent / p):
        if cand.exists():
            return cand
    return None


def _same(d: Mapping[str, Any], again: Mapping[str, Any]) -> bool:
    """The re-run found the same effects and the same misfit as the JSON says."""
    names = [e["name"] for e in d.get("effects") or []]
    before = (d.get("mismatch") or {}).get("nrmse_before")
    now = again["mismatch"]["nrmse_before"]
    return (names == [e["name"] for e in again["effects"]] and before is not None
            and math.isclose(float(before), float(now), rel_tol=1e-6))


def rerun(d: Mapping[str, Any], json_path: Path) -> tuple[Any, str]:
    """(DiagnoseResult, "") when the diagnosis can be repeated as the JSON describes it,
    else (None, why not)."""
    from ..bagio.spans import read_excerpt
    from ..core.discrepancy import DiagnoseOptions, diagnose
    from ..core.physics.plant import plant_from_dict

    real = _find(d.get("real"), json_path)
    if real is None:
        return None, (f"the recording {d.get('real')!r} named by the diagnose JSON is not "
                      "there" if d.get("real") else "the diagnose JSON names no recording")
    val = _find(d.get("validate"), json_path)
    if d.get("validate") and val is None:
        return None, f"the held-out recording {d.get('validate')!r} is not there"
    method = d.get("method") or {}
    replay = any((f or {}).get("output_error") for f in (d.get("fit") or {}).values())
    defaults = DiagnoseOptions()
    opts = DiagnoseOptions(alpha=float(method.get("alpha", defaults.alpha)),
                           min_share=float(method.get("min_share", defaults.min_share)),
                           replay=replay,
                           max_samples=int(method.get("max_samples", defaults.max_samples)))

    def read(path: Path, split: float | None) -> Any:  # the spans the diagnosis used
        return read_excerpt(path, max_samples=opts.max_samples, split=split)

    split = None if val else opts.split
    sim = _find(d.get("sim"), json_path)
    if d.get("reference") == "sim_recording" and sim is None:
        return None, f"the simulator's recording {d.get('sim')!r} is not there"
    try:
        held = read(val, None) if val else None
        if sim is not None:
            from ..core.discrepancy.against import diagnose_sim

            result = diagnose_sim(read(sim, opts.split), read(real, split), held, opts)
        else:
            result = diagnose(plant_from_dict(d["plant"]), read(real, split), held, opts)
    except (PmsmSysidError, KeyError, TypeError, ValueError) as exc:
        return None, f"the diagnosis could not be repeated ({exc})"
    if not _same(d, result.to_dict()):
        return None, ("repeating the diagnosis on the recordings found today gave other "
                      "results than the JSON (were the recordings changed?)")
    return result, ""


def figure_section(result: Any, sink: Any) -> Section:
    """The diagnosis figures (:func:`pmsm_sysid.plots.diagnose.figures`) as a section."""
    from ..plots.diagnose import figures

    images = tuple(sink.figure(plot) for plot in figures(result))
    return Section("Sim-to-real: figures", images)


def _param(key: str, value: Any, std: Any) -> tuple[str, str]:
    """(name, value with its standard error and unit) of one effect parameter."""
    name, unit = key, ""
    for suffix, u in UNITS:
        if key.endswith(suffix):
            name, unit = key[: -len(suffix)], u
            break
    if isinstance(value, list):
        text = ", ".join(f"order {h['order']}: {float(h['amplitude_n']):.3g} N"
                         if isinstance(h, dict) and "order" in h else _v(h) for h in value)
        return name, text or "none"
    text = _v(value)
    if isinstance(value, float) and isinstance(std, float) and math.isfinite(std):
        text = f"{value:.5g} ± {std:.2g}"
    return name.replace("_", " "), f"{text} {unit}".strip()


def _evidence(e: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    sig = float(e.get("significance") or 0.0)
    rows = [("confidence", str(e.get("confidence", "n/a"))),
            ("evidence", f"p = {10.0 ** -min(sig, 300.0):.2g} on the estimation data "
                         f"(family-wise, Bonferroni-corrected F-test)"),
            ("explains", f"{100 * float(e.get('explains') or 0):.1f}% of the nominal "
                         "plant's force residual")]
    h = e.get("held_out")
    if h:
        rows.append(("held-out data", f"mean-square residual {-100 * float(h['reduction']):+.0f}%"
                     f" (z = {float(h['z']):.1f}): "
                     + ("confirmed" if h.get("confirmed") else "not confirmed")))
    alt = e.get("alternative")
    if alt:
        rows.append(("preferred over", f"{alt.get('name')} (Δχ² = "
                     f"{float(alt.get('delta_chi2', math.nan)):.1f})"))
    rows += [("note", str(n)) for n in e.get("notes") or []]
    return tuple(rows)


def effect_sections(d: Mapping[str, Any], result: Any,
                    draw: Callable[[Any], Image], why: str = "") -> list[Section]:
    """One section per named effect of the diagnose JSON ``d``: parameters, confidence,
    evidence and its before/after figure (drawn from ``result``, the repeated diagnosis;
    when it is None the section says ``why`` instead)."""
    from ..plots.diagnose import effect_before_after, unexplained_curve

    out = []
    for e in d.get("effects") or []:
        std = e.get("params_std") or {}
        params = tuple(_param(k, v, std.get(k)) for k, v in (e.get("params") or {}).items()
                       if not k.endswith(HIDDEN))
        if e["name"] == "unexplained":
            params = (("what", unexplained_text(e.get("params") or {})),)
        blocks: list[Block] = [Facts(params or (("parameters", "none"),)),
                               Facts(_evidence(e))]
        if e["name"] == "unexplained":
            try:  # the JSON keeps the curve itself: no repeated diagnosis needed
                blocks.append(draw(unexplained_curve(dict(e.get("params") or {}))))
            except PmsmSysidError as exc:
                blocks.append(Note(f"figure not drawn: {exc}"))
        elif result is None:
            blocks.append(Note(f"before/after figure not drawn: {why}"))
        else:
            try:
                blocks.append(draw(effect_before_after(result, str(e["name"]))))
            except PmsmSysidError as exc:
                blocks.append(Note(f"before/after figure not drawn: {exc}"))
        out.append(Section(f"Effect: {e['name']}", tuple(blocks)))
    return out


def write_report(result: Any, out_dir: str | Path, title: str = "") -> Path:
    """Save the figures as PNG in ``out_dir`` and write the one-file page ``index.html``."""
    from ..plots.base import save
    from ..plots.diagnose import figures
    from ..progress import Bar
    from .html import image, write_page

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    images = []
    doc = result.to_dict()
    with Bar(4 + bool(result.curves.replay) + len(doc["effects"]), "report") as bar:
        for plot in figures(result):
            images.append(image(save(plot, out), plot.caption))
            plot.figure.clear()
            bar.update()

        def draw(p: Any) -> Image:
            bar.update()
            return image(save(p, out), p.caption)

        pages = json_sections(doc)
        pages.insert(2, Section("Sim-to-real: figures", tuple(images)))
        pages[3:3] = effect_sections(doc, result, draw)
    return write_page(out, f"pmsm-sysid diagnose: {title}" if title else "pmsm-sysid diagnose",
                      pages)
