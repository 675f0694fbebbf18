"""Report sections of a sim-to-real diagnosis (the ``diagnose`` JSON, contract §3): where the
mismatch lives, the named effects with their parameters, the corrected plant and the fit
table before/after. Figures need the diagnosis' series, which the JSON does not carry; they
are drawn by ``diagnose --report DIR`` (figure functions in :mod:`pmsm_sysid.plots.diagnose`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .html import Block, Facts, Note, Section, Table


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
    return Facts(tuple((str(k), _v(v)) for k, v in p.items() if not isinstance(v, dict)))


def effects_table(d: Mapping[str, Any]) -> Table:
    rows = tuple((str(e["name"]), _v({k: v for k, v in (e.get("params") or {}).items()
                                      if not k.endswith("_means_n")}),
                  _v(e.get("significance")), f"{100 * float(e.get('explains') or 0):.1f}%",
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


def where_table(d: Mapping[str, Any]) -> Table:
    rows = tuple((str(w.get("axis")), f"{100 * float(w.get('share') or 0):.1f}%",
                  _v(w.get("significance")))
                 for w in (d.get("mismatch") or {}).get("where") or [])
    return Table("Where the nominal plant's residual lives", ("axis", "share", "significance"),
                 rows)


def json_sections(d: Mapping[str, Any]) -> list[Section]:
    mism = d.get("mismatch") or {}
    summary: list[Block] = [Facts((("NRMSE before", _v(mism.get("nrmse_before"))),
                                   ("effects found", str(len(d.get("effects") or []))))),
                            where_table(d)]
    if not d.get("effects"):
        summary.append(Note("no significant missing physics"))
    found: list[Block] = [effects_table(d), fit_table(d)]
    found += [Note(str(n)) for n in d.get("notes") or []]
    found.append(Note("residual figures are drawn by 'pmsm-sysid diagnose ... --report DIR' "
                      "(the JSON holds no series)"))
    plants: list[Block] = [_plant(d.get("plant") or {})]
    return [Section("Sim-to-real: where the mismatch lives", tuple(summary)),
            Section("Sim-to-real: named effects and fit", tuple(found)),
            Section("Nominal plant", tuple(plants)),
            Section("Corrected plant", (_plant(d.get("corrected_plant") or {}),))]
