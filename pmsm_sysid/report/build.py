"""``build_report``: a recording or a result JSON to ``DIR/index.html`` and its PNGs.

=====================  =====================================================================
input                  report
=====================  =====================================================================
recording (bag dir)    identify with the given protocol (default: the paper's speed case),
                       then GFRFs; every figure; ``identify.json`` and ``gfrf.json`` beside
identify JSON          its model's figures; the time-domain ones from the recording named
                       by its ``source`` key (when found; otherwise the page says why)
``run --json`` summary  the run over time from its window-by-window history (fit, terms,
                       H1 peak, change score, latency), then its ``last_model`` as an
                       identify JSON without a recording
gfrf JSON              peak and ridge tables; the GFRF figures when it carries ``grid``
diagnose JSON          its tables; its figures by repeating the diagnosis on the recordings
                       it names (when found and reproduced; otherwise the page says why)
=====================  =====================================================================
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.errors import DataError, PmsmSysidError
from ..core.selection.identify import FitConfig
from .html import Facts, Note, Section, write_page
from .sink import Sink

SERIES_FIGURES = 6  # io, psd, predicted x2, correlation (+1 spare for validation absent)
FREQ_FIGURES = 4
DIAGNOSE_FIGURES = 5


@dataclass(frozen=True)
class ReportOptions:
    """Identification protocol used when the report starts from a recording."""

    input: str = "thrust"
    output: str = "speed"
    config: FitConfig = field(default_factory=FitConfig)
    estimate: tuple[int, int] = (1000, 2000)
    validate: tuple[int, int] | None = (3000, 4000)
    corr_lags: int = 20
    form: str = "level"


@dataclass(frozen=True)
class ReportResult:
    """What was written; ``data`` holds, per figure name, what that figure drew."""

    index: Path
    kind: str
    figures: tuple[Path, ...]
    data: Mapping[str, Mapping[str, Any]]
    notes: tuple[str, ...] = ()
    extra_files: tuple[Path, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"index": str(self.index), "kind": self.kind,
                "figures": [p.name for p in self.figures],
                "files": [p.name for p in self.extra_files], "notes": list(self.notes)}


def _dump(obj: Any, path: Path) -> Path:
    from ..core.frequency.analysis import json_safe

    path.write_text(json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n")
    return path


def _prepare(out_dir: str | Path) -> Path:
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"--out {out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"--out {out}: cannot create ({exc.strerror})") from exc
    return out


def _finish(sink: Sink, title: str, sections: list[Section], kind: str,
            subtitle: str = "", extra: tuple[Path, ...] = ()) -> ReportResult:
    index = write_page(sink.out_dir, title, sections, subtitle)
    sink.bar.finish()
    return ReportResult(index=index, kind=kind, figures=tuple(sink.files), data=dict(sink.data),
                        notes=tuple(sink.notes), extra_files=extra)


def report_bag(bag: str | Path, out_dir: str | Path,
               options: ReportOptions | None = None) -> ReportResult:
    """Identify a recording (``options``), then report everything (module docstring)."""
    from ..bagio import read_recording
    from ..core.selection.identify import identify_recording

    opt = options or ReportOptions()
    out = _prepare(out_dir)
    sink = Sink(out, 4 + SERIES_FIGURES + FREQ_FIGURES)
    try:
        rec = read_recording(bag).recording
        sink.tick()
        res = identify_recording(rec, input=opt.input, output=opt.output, config=opt.config,
                                 estimate=opt.estimate, validate=opt.validate,
                                 max_lag_corr=opt.corr_lags, form=opt.form)
        sink.tick()
        d = res.to_dict()
        d["source"] = str(Path(bag).resolve())
        files = (_dump(d, out / "identify.json"),)
        return _identify(d, rec, sink, files, f"recording {Path(bag).name}")
    finally:
        sink.close()


def _identify(d: dict[str, Any], rec: Any, sink: Sink, files: tuple[Path, ...],
              what: str, why: str = "", before: tuple[Section, ...] = (),
              title: str = "Validation: fit and correlation tests") -> ReportResult:
    from ..core.frequency.analysis import analyse_json
    from ..core.terms.model import NarxModel
    from . import frequency, identify

    model = NarxModel.from_dict(d)
    if rec is not None and d.get("estimate"):
        signals, validation = identify.series_sections(d, model, rec, sink)
        sections = [signals, identify.model_section(d), validation]
    else:
        sections = [*before, identify.model_section(d),
                    *identify.json_only_sections(d, why or "no recording", title)]
    try:
        g = analyse_json(d).to_dict()
    except PmsmSysidError as exc:
        sink.notes.append(f"GFRFs not computed: {exc}")
        sections.append(Section("Frequency domain", (Facts((("GFRFs", str(exc)),)),)))
    else:
        sink.tick()
        files = (*files, _dump(g, sink.out_dir / "gfrf.json"))
        sections += frequency.model_sections(model, g, sink, d)
    return _finish(sink, f"pmsm-sysid report: {what}", sections, "identify",
                   f"{d.get('input')} → {d.get('output')}, {len(d['terms'])} terms",
                   extra=files)


def _source(d: Mapping[str, Any], json_path: Path) -> tuple[Path | None, str]:
    """The recording an identify JSON names, tried as given and beside the JSON."""
    src = d.get("source")
    if not src:
        return None, ("the identify JSON names no recording ('source'); report the bag "
                      "itself to draw them")
    p = Path(str(src))
    for cand in (p, json_path.parent / p) if not p.is_absolute() else (p,):
        if cand.is_dir() or cand.is_file():
            return cand, ""
    return None, f"the identify JSON's 'source' is not a recording found here ({src!r})"


def report_identify(d: dict[str, Any], json_path: Path, out_dir: str | Path) -> ReportResult:
    """An identify JSON: model and GFRF figures, time-domain ones from its recording."""
    from ..bagio import read_recording

    out = _prepare(out_dir)
    sink = Sink(out, 3 + SERIES_FIGURES + FREQ_FIGURES)
    try:
        path, why = _source(d, json_path)
        rec = None
        if path is not None:
            rec = read_recording(path).recording
        sink.tick()
        return _identify(d, rec, sink, (), json_path.name, why)
    finally:
        sink.close()


def report_summary(d: Mapping[str, Any], out_dir: str | Path) -> ReportResult:
    """A run summary held in memory (``run --report``): written beside the page as
    ``run.json``, then reported as :func:`report_run` does."""
    out = _prepare(out_dir)
    path = _dump(d, out / "run.json")
    return report_run(d, path, out, extra=(path,))


def report_run(d: Mapping[str, Any], json_path: Path, out_dir: str | Path,
               extra: tuple[Path, ...] = ()) -> ReportResult:
    """A ``run --json`` summary: the run over time (models, diagnoses), then its last
    model (when one was fitted)."""
    from . import run

    out = _prepare(out_dir)
    if not isinstance(d.get("last_model"), dict):
        sink = Sink(out, 2)
        try:
            return _finish(sink, "pmsm-sysid report: live run", run.sections(d, sink), "run",
                           "no model was fitted", extra=extra)
        finally:
            sink.close()
    sink = Sink(out, 7 + FREQ_FIGURES)
    try:
        before = tuple(run.sections(d, sink))
        model = dict(d["last_model"])
        model.pop("source", None)
        seq = (model.get("window") or {}).get("seq")
        return _identify(model, None, sink, (), json_path.name,
                         "a live run keeps no recording in its summary", before,
                         f"The last {model.get('output', '')} model (window {seq}): its fit and "
                         "correlation tests; the run's windows are judged in Live run above")
    finally:
        sink.close()


def report_gfrf(g: Mapping[str, Any], json_path: Path, out_dir: str | Path) -> ReportResult:
    from . import frequency

    sink = Sink(_prepare(out_dir), 1 + 3)
    try:
        sections = frequency.json_sections(g, sink)
        return _finish(sink, f"pmsm-sysid report: {json_path.name}", sections, "gfrf")
    finally:
        sink.close()


def report_diagnose(d: Mapping[str, Any], json_path: Path, out_dir: str | Path) -> ReportResult:
    """A diagnose JSON: its tables; the figures by repeating the diagnosis it describes."""
    from . import diagnose

    sink = Sink(_prepare(out_dir), 2 + DIAGNOSE_FIGURES + len(d.get("effects") or []))
    try:
        sections = diagnose.json_sections(d)
        result, why = diagnose.rerun(d, json_path)
        sink.tick()
        if result is not None:
            sections.insert(2, diagnose.figure_section(result, sink))
        else:
            sink.notes.append(f"diagnosis figures not drawn: {why}")
            sections.insert(2, Section("Sim-to-real: figures", (Note(sink.notes[-1]),)))
        sections[3:3] = diagnose.effect_sections(d, result, sink.figure, why)
        return _finish(sink, f"pmsm-sysid report: {json_path.name}", sections, "diagnose")
    finally:
        sink.close()


def kind_of(d: Any) -> str:
    """Which result a JSON holds: identify, run, gfrf or diagnose (DataError otherwise)."""
    if isinstance(d, dict):
        if "terms" in d:
            return "identify"
        if isinstance(d.get("last_model"), dict) or isinstance(d.get("last_diagnosis"), dict):
            return "run"
        if "h1" in d and "h2" in d:
            return "gfrf"
        if "effects" in d and "fit" in d:
            return "diagnose"
    raise DataError("not a result JSON of identify, gfrf, diagnose or run --json")


def report_json(path: str | Path, out_dir: str | Path) -> ReportResult:
    """Report a result JSON (kind detected from its keys)."""
    from ..validate import read_json_object

    p = Path(path)
    d = read_json_object(str(p), "a result JSON of identify, gfrf, diagnose or run --json")
    try:
        kind = kind_of(d)
    except DataError as exc:
        raise DataError(f"{p}: {exc}") from exc
    if kind == "gfrf":
        return report_gfrf(d, p, out_dir)
    if kind == "diagnose":
        return report_diagnose(d, p, out_dir)
    if kind == "run":
        return report_run(d, p, out_dir)
    return report_identify(d, p, out_dir)


def build_report(source: str | Path, out_dir: str | Path,
                 options: ReportOptions | None = None) -> ReportResult:
    """A recording directory (or .mcap/.db3 file) or a result JSON to ``out_dir``."""
    p = Path(source)
    if not p.exists():
        raise DataError(f"{p}: no such file or directory")
    if p.is_file() and p.suffix.lower() == ".json":
        return report_json(p, out_dir)
    return report_bag(p, out_dir, options)
