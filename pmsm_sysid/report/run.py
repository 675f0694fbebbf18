"""Report sections of a live run (the ``run --json`` summary): the run in numbers, and the
models over time from its window-by-window ``history`` (:mod:`pmsm_sysid.plots.history`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..core.online.history import CHANGE_NAMES
from .html import Block, Facts, Note, Section, Table
from .sink import Sink


def _n(x: Any, fmt: str = "{:.3g}") -> str:
    return "n/a" if x is None else fmt.format(x)


def facts(d: Mapping[str, Any]) -> Facts:
    return Facts((
        ("nodes", ", ".join(d.get("nodes") or []) or "n/a"),
        ("clock", str(d.get("clock", "n/a"))),
        ("samples", f"received {_n(d.get('samples_received'), '{}')}, dropped "
                    f"{_n(d.get('samples_dropped'), '{}')}, missing "
                    f"{_n(d.get('samples_missing'), '{}')}"),
        ("windows", f"fitted {_n(d.get('windows_fitted'), '{}')}, skipped "
                    f"{_n(d.get('windows_skipped'), '{}')}, failed "
                    f"{_n(d.get('windows_failed'), '{}')}"),
        ("fit latency", f"median {_n(d.get('fit_latency_p50_ms'))} ms, 99th percentile "
                        f"{_n(d.get('fit_latency_p99_ms'))} ms"),
        ("change events", str(len(d.get("change_events") or []))),
        *verdict_facts(d),
        *_diagnosis_facts(d),
    ))


def verdict_facts(d: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The run's verdict and, per output, its windows judged together: as many failures
    as a correct model has (1 in 20 by chance), or more (a binomial test at 1 %, widened for
    the windows' overlap)."""
    from ..core.validation.windows import grid_shift, window_rate

    out: list[tuple[str, str]] = []
    v = d.get("verdict") or {}
    if v.get("status"):
        named = [*v.get("failures", []), *v.get("warnings", [])]
        out.append(("verdict", v["status"] + (f": {'; '.join(named)}" if named else "")))
    for output, count in (d.get("validation_counts") or {}).items():
        r = window_rate(count[0], count[1], shift=grid_shift(d.get("window_grid")))
        judged = ("consistent with a correct model, which fails 1 in 20 by chance"
                  if r["consistent"] else "more than chance explains (a correct model fails "
                  "1 in 20)")
        out.append((f"{output} windows", f"{r['passed']}/{r['windows']} passed their "
                    f"cross-validation, {r['failed']} failed: {judged}; p = "
                    f"{r['p_value']:.2g}"))
    return out


def _diagnosis_facts(d: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    if d.get("diagnoses_run") is None:
        return ()
    from ..diagnosed import found_text

    last = d.get("last_diagnosis")
    return (("diagnoses", f"run {d['diagnoses_run']}, skipped "
                          f"{_n(d.get('diagnoses_skipped'), '{}')}, failed "
                          f"{_n(d.get('diagnoses_failed'), '{}')}"),
            ("latest diagnosis", found_text(last) if last else "none"))


def events_table(hist: Mapping[str, Any]) -> Table:
    t0 = min((r["t"] for rows in hist["outputs"].values() for r in rows
              if r.get("t") is not None), default=0.0)
    rows = tuple((str(e.get("output")),
                  _n(None if e.get("t") is None else e["t"] - t0, "{:.1f}"),
                  ", ".join(CHANGE_NAMES.get(r, r) for r in e.get("reasons") or []))
                 for e in hist.get("events") or [])
    return Table("Change events (time since the first window, s)",
                 ("output", "time (s)", "what moved"), rows)


def sections(d: Mapping[str, Any], sink: Sink) -> list[Section]:
    """The run in numbers and, when the summary holds a history, its figures over time."""
    from ..plots.history import figures

    hist = d.get("history")
    blocks: list[Block] = [facts(d)]
    spans = ((hist or {}).get("diagnosis") or {}).get("rows") or []
    if not hist or not (any(hist.get("outputs", {}).values()) or spans):
        blocks.append(Note("this summary holds no window-by-window history (written by an "
                           "older version, or no identification ran): only the last model is "
                           "shown"))
        return [Section("Live run", tuple(blocks))]
    stride = max((hist.get("stride") or {}).values(), default=1)
    if stride > 1:
        blocks.append(Note(f"long run: the history keeps every {stride}th window"))
    plots = figures(hist)
    out = [Section("Live run", tuple(blocks))]
    models = [sink.figure(p) for p in plots if p.name != "run_diagnosis"]
    if models:
        out.append(Section("Live run: models over time", (*models, events_table(hist))))
    if spans:
        diag = next(p for p in plots if p.name == "run_diagnosis")
        out.append(Section("Live run: diagnosis over time",
                           (sink.figure(diag), diagnosis_table(hist))))
    return out


def diagnosis_table(hist: Mapping[str, Any]) -> Table:
    """The spans whose diagnosis named something (at most the last 50)."""
    from ..plots.history import _t0

    t0 = _t0(hist)
    diag = hist.get("diagnosis") or {}
    named = [r for r in diag.get("rows") or [] if r.get("effects")]
    rows = tuple((_n(None if r.get("t") is None else r["t"] - t0, "{:.1f}"),
                  ", ".join(r["effects"])) for r in named[-50:])
    stride = int(diag.get("stride") or 1)
    kept = f"; the history keeps every {stride}th span" if stride > 1 else ""
    return Table(f"Spans that named missing physics: {len(named)} of "
                 f"{len(diag.get('rows') or [])}{kept} (time of the span's end since the "
                 "first window, s)", ("time (s)", "effects"), rows)
