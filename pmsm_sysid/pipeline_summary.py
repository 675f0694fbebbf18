"""The ``run --json`` summary of a :class:`.app.Pipeline`: what each node of this process
counted (samples, windows, models, ridges, validation, changes), the diagnosis and the
recording, read from the running nodes (counters of a node this process does not run are
null)."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from .diagnosed import diagnosis_summary, run_history
from .pipeline_nodes import NODES

if TYPE_CHECKING:
    from .app import Pipeline


def _pick(by_output: Mapping[str, Any], order: Sequence[str]) -> Any:
    for name in order:
        if name in by_output:
            return by_output[name]
    return next(iter(by_output.values()), None)


def pipeline_summary(pipe: Pipeline) -> dict[str, Any]:
    """Keys (samples_received, samples_dropped, windows_fitted, windows_skipped,
    last_model, last_ridges, last_validation) plus change_events and per-node details.
    Counters of a node this process does not run are null."""
    ident, gfrf, sim = pipe.identifier, pipe.gfrf, pipe.sim
    col = pipe.nodes.get("collector")
    out: dict[str, Any] = {
        "nodes": [n for n in NODES if n in pipe.nodes], "clock": pipe.clock,
        "wall_time_s": time.monotonic() - pipe.started,
        "samples_published": sim.published if sim is not None else None,
    }
    keys = ("samples_received", "samples_dropped", "samples_missing", "unaligned",
            "out_of_order", "duplicates", "clock_restarts", "rate_changes", "windows_due",
            "windows_fitted", "windows_skipped",
            "windows_failed", "fit_latency_p50_ms", "fit_latency_p99_ms", "fit_cpu_s")
    stats = ident.engine.stats.to_dict() if ident is not None else {}
    out.update({k: stats.get(k) for k in keys})
    order = list(ident.params["outputs"]) if ident is not None else ["speed", "position"]
    models = dict(ident.last["models"]) if ident is not None else dict(col.models if col else {})
    ridges = dict(col.ridges) if col is not None else {}
    if not ridges and gfrf is not None and gfrf.last_ridges:
        ridges = {str(gfrf.last_ridges.get("output")): gfrf.last_ridges}
    vals = dict(ident.last["validation"]) if ident is not None else {}
    out.update({
        "last_model": _pick(models, order), "last_ridges": _pick(ridges, order),
        "last_validation": _pick(vals, order), "last_models": models,
        "last_ridges_by_output": ridges, "last_validations": vals,
        "validation_counts": ({k: list(v) for k, v in ident.validation_counts.items()}
                              if ident is not None else {}),
        "window_grid": ident.window_grid() if ident is not None else None,
        "models_published": ident.models_published if ident is not None else None,
        "change_events": (list(ident.last["changes"]) if ident is not None
                          else list(col.changes) if col is not None else []),
        "errors": list(ident.errors) if ident is not None else [],
        "history": run_history(col),
        "inputs": ident.input_report().to_dict() if ident is not None else None,
        "speed_derived": ident.engine.aligner.speed_derived if ident is not None else None,
    })
    if gfrf is not None:
        g = gfrf.summary()
        out["gfrf"] = {k: v for k, v in g.items() if not k.startswith("last_")}
    out.update(diagnosis_summary(pipe.diagnose, col))
    if pipe.recorder is not None:
        out.update(record_summary(pipe))
    return out


def record_summary(pipe: Pipeline) -> dict[str, Any]:
    """What the recorder wrote and what it lost: per input topic, the samples published
    here that are not in the bag, or (sim elsewhere) the samples its stamps skip."""
    res = pipe.record_result or {}
    topics: dict[str, int] = res.get("topics", {})
    missing: dict[str, int] = res.get("samples_missing", {})
    inputs = pipe.recorder.inputs
    if pipe.sim is not None:
        lost = max((pipe.sim.published - topics.get(t, 0) for t in inputs), default=0)
    elif pipe.identifier is not None:  # received here but not recorded, or skipped stamps
        got = pipe.identifier.engine.stats.samples_received
        never = set(pipe.identifier.input_report().missing)  # e.g. no speed: derived
        inputs = [t for t in inputs if t not in never]
        lost = max((max(got - topics.get(t, 0), missing.get(t, 0)) for t in inputs), default=0)
    else:
        lost = max((missing.get(t, 0) for t in inputs), default=0)
    return {"record": str(pipe.recorder.path), "record_error": pipe.record_error,
            "recorded_messages": res.get("messages") if res else None,
            "recorded_by_topic": topics, "record_samples_lost": lost if res else None,
            "record_stamp_gaps": sum(res.get("stamp_gaps", {}).values()) if res else None}
