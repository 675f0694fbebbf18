"""The verdict of a ``pmsm-sysid run`` summary, and its one-line form.

An output is judged by its run, not by its latest window. Each window's model is
cross-validated (free run on the next window, the five correlation tests of Billings & Voon
on its estimation residuals, Liu et al. 2005 Eq. 13), and the tests reject a correct model in
some windows by chance: by their own rule, 4.1 % of the windows for white residuals
(:func:`~pmsm_sysid.core.validation.window_false_rejection_rate`); the default run's
outputs measured 3.8 to 5.1 %. The run's count of failed windows is therefore compared with
:data:`NULL_RATE` (1 in 20) by a one-sided test (:mod:`pmsm_sysid.core.validation.windows`:
binomial, widened for the windows' overlap, since overlapping windows pass and fail
together): an output fails when P(X >= failed) < :data:`LEVEL` (1 %), i.e. when its windows
fail clearly more often than a correct model's do; the latest window's result is then a
detail of the line. The run summary's ``window_grid`` (window and hop) gives the overlap.

Status ``pass``: every identified output's windows pass at a rate consistent with a correct
model and its latest free run holds, no fit failed, no data-check warning on the latest
models, no change event, nothing dropped or skipped. ``FAIL``: a fit failed, the recording
lost samples, an output's latest free run diverged or fell below ``min_r2``, or its windows
failed significantly more often than 1 in 20. ``warning``: everything else that is not a
pass, named (a failed window among too few to judge, data-check warnings, change events,
dropped samples, skipped windows, an input problem, an output not validated yet, and with
the live diagnosis: physics its latest span found missing from the reference, spans skipped
or not diagnosed).
"""

from __future__ import annotations

import math
from typing import Any

from ..clocktext import stamp_text
from ..core.validation.windows import LEVEL, NULL_RATE, grid_shift, window_rate

__all__ = ["LEVEL", "NULL_RATE", "headline", "verdict", "window_rate"]


def _failure(v: dict[str, Any]) -> str:
    """Why a cross-validation failed, in words."""
    fr = v["free_run"]
    reasons = []
    if fr.get("diverged"):
        reasons.append("free run diverged on the next window")
    elif fr.get("r2") is None or fr["r2"] < v["min_r2"]:
        r2 = "n/a" if fr.get("r2") is None else f"{fr['r2']:.4f}"
        reasons.append(f"free-run R2 {r2} < {v['min_r2']:g} on the next window")
    failed = [k for k, t in v["correlation_tests"].items() if not t["pass"]]
    if failed:
        reasons.append(f"correlation test{'s' if len(failed) > 1 else ''} "
                       f"{', '.join(failed)} failed on its estimation window")
    return "; ".join(reasons) or "failed"


def _free_run_fails(v: dict[str, Any]) -> bool:
    fr = v["free_run"]
    return bool(fr.get("diverged") or fr.get("r2") is None or fr["r2"] < v["min_r2"])


def _judge_output(name: str, v: dict[str, Any] | None, count: list[int] | None,
                  shift: float) -> tuple[str, str]:
    """(status, text) of one output: its run's windows first, the latest window a detail."""
    if v is None:
        return "warning", f"{name} not validated yet"
    tests = v["correlation_tests"]
    n_pass = sum(bool(t["pass"]) for t in tests.values())
    r2 = "n/a" if v["free_run"].get("r2") is None else f"{v['free_run']['r2']:.4f}"
    if _free_run_fails(v):
        runs = f", {count[0]}/{count[1]} windows passed" if count else ""
        return "FAIL", f"{name} validation FAIL: {_failure(v)} (free-run R2 {r2}{runs})"
    if not count:
        if v["pass"]:
            return "pass", (f"{name} validation pass (free-run R2 {r2}, correlation tests "
                            f"{n_pass}/{len(tests)})")
        return "warning", f"{name} latest validation failed: {_failure(v)} (free-run R2 {r2})"
    rate = window_rate(count[0], count[1], shift=shift)
    runs = f"{count[0]}/{count[1]} windows passed"
    latest = ("the latest window passed" if v["pass"]
              else f"the latest window: {_failure(v)}")
    if not rate["consistent"]:
        return "FAIL", (f"{name} validation FAIL: {rate['failed']} of {rate['windows']} "
                        f"windows failed, more than the 1 in 20 a correct model fails by "
                        f"chance (p = {rate['p_value']:.2g} < {LEVEL:g}); {latest} "
                        f"(free-run R2 {r2}, {runs})")
    if v["pass"]:
        return "pass", (f"{name} validation pass (free-run R2 {r2}, correlation tests "
                        f"{n_pass}/{len(tests)}, {runs})")
    if not rate["judged"]:
        return "warning", (f"{name} validation: {runs}, too few windows to judge the run; "
                           f"{latest} (free-run R2 {r2})")
    return "pass", (f"{name} validation pass (free-run R2 {r2}, {runs}: as often as a "
                    f"correct model, which fails 1 window in 20 by chance; {latest})")


def _data_check(name: str, model: dict[str, Any] | None) -> str | None:
    check = (model or {}).get("data_check") or {}
    warnings = check.get("warnings") or []
    if not warnings:
        return None
    first = str(warnings[0]).split(":")[0]
    if "excitation" in first and check.get("pe_order") is not None:
        first += (f" (persistently exciting of order {check['pe_order']} < "
                  f"{check['pe_required']} input lags)")
    more = f" and {len(warnings) - 1} more" if len(warnings) > 1 else ""
    return f"{name} data check: {first}{more}"


def verdict(s: dict[str, Any]) -> dict[str, Any]:
    """``{"status": "pass" | "warning" | "FAIL" | "none", "failures": [...],
    "warnings": [...], "outputs": [...], "windows": {output: window_rate(...)}}`` of a run
    summary (see the module doc; "none": nothing identified in this process, e.g.
    ``--nodes sim``)."""
    vals = s.get("last_validations") or {}
    models = s.get("last_models") or {}
    counts = s.get("validation_counts") or {}
    names = list(dict.fromkeys([*models, *vals]))
    failures: list[str] = []
    warnings: list[str] = []
    outputs: list[str] = []
    windows: dict[str, Any] = {}
    shift = grid_shift(s.get("window_grid"))
    for name in names:
        status, text = _judge_output(name, vals.get(name), counts.get(name), shift)
        outputs.append(text)
        if counts.get(name):
            windows[name] = window_rate(counts[name][0], counts[name][1], shift=shift)
        if status != "pass":
            (failures if status == "FAIL" else warnings).append(text)
        check = _data_check(name, models.get(name))
        if check:
            warnings.append(check)
    errors = s.get("errors") or []
    if errors:
        failures.append(f"{len(errors)} fit error(s), last: {errors[-1]}")
    changes = s.get("change_events") or []
    if changes:
        where = ", ".join(f"{c['output']} at {stamp_text(c['window']['end_stamp'], 2)} "
                          f"({', '.join(c['reasons'])})" for c in changes[-3:])
        last = "the last 3: " if len(changes) > 3 else ""
        warnings.append(f"{len(changes)} change event(s): {last}{where}")
    inputs = s.get("inputs") or {}
    if inputs.get("problem"):
        warnings.append(str(inputs["problem"]))
    if s.get("recorded_messages") is not None and s.get("record_samples_lost"):
        failures.append(f"recording lost {s['record_samples_lost']} samples")
    elif s.get("record") and s.get("recorded_messages") is None:
        failures.append(f"recording not finalised ({s.get('record_error') or 'counts unknown'})")
    for key, label in (("samples_dropped", "samples dropped"),
                       ("samples_missing", "samples missing"),
                       ("windows_skipped", "windows skipped")):
        if s.get(key):
            warnings.append(f"{s[key]} {label}")
    warnings += diagnosis_warnings(s)
    if not names and s.get("samples_received") is not None:
        warnings.append("no model fitted yet")
    if not names and not failures and not warnings:  # no identifier in this process
        status = "none"
    else:
        status = "FAIL" if failures else "warning" if warnings else "pass"
    return {"status": status, "failures": failures, "warnings": warnings, "outputs": outputs,
            "windows": windows}


def diagnosis_warnings(s: dict[str, Any]) -> list[str]:
    """What the live diagnosis found missing in its latest span, and the spans it could not
    diagnose (skipped to keep up, or failed)."""
    from ..diagnosed import found_text, mismatch

    out = []
    last = s.get("last_diagnosis")
    if last and mismatch(last):
        lacks = "the simulation" if last.get("reference") == "sim_recording" else "the plant"
        end = (last.get("window") or {}).get("end_stamp")
        where = (f" (span ending at {stamp_text(float(end), prefix='t=')})"
                 if end is not None else "")
        out.append(f"missing from {lacks}{where}: {found_text(last)}")
    if s.get("diagnoses_skipped"):
        out.append(f"{s['diagnoses_skipped']} span(s) not diagnosed (skipped: diagnoses "
                   "slower than diagnose.period_s)")
    if s.get("diagnoses_failed"):
        errors = (s.get("diagnose") or {}).get("errors") or ["?"]
        out.append(f"{s['diagnoses_failed']} diagnosis(es) failed, last: {errors[-1]}")
    return out


def _diagnosis_text(s: dict[str, Any]) -> str | None:
    if s.get("diagnoses_run") is None:
        return None
    from ..diagnosed import found_text

    last = s.get("last_diagnosis")
    text = f"latest diagnosis: {found_text(last)}" if last else "no diagnosis yet"
    return f"{text} ({s['diagnoses_run']} run, {s.get('diagnoses_skipped') or 0} skipped)"


def _h1_text(r: dict[str, Any]) -> str:
    """The strongest H1 peak; a low-pass one (at 0 Hz) by its gain and pole's corner."""
    top = max(r["h1"]["peaks"], key=lambda p: p["gain_db"] or -1e300)
    radius = top.get("pole_radius")
    if top.get("kind") == "dc" and top.get("gain_db") is not None and radius and 0 < radius < 1:
        corner = -math.log(radius) * float(r["sample_rate_hz"]) / (2 * math.pi)
        return (f"{r.get('output', '')} H1 low-pass {top['gain_db']:.2f} dB at 0 Hz, pole "
                f"{radius:.4f} (corner {corner:.2f} Hz)").lstrip()
    return f"H1 peak {top['freq_hz']:.2f} Hz"


def headline(s: dict[str, Any]) -> str:
    """The one-line summary: verdict first, then what failed or the figures of a pass."""
    v = s.get("verdict") or verdict(s)
    named = [*v["failures"], *v["warnings"]]
    parts = [*named, *(o for o in v["outputs"] if o not in named)]
    if s["samples_published"] is not None:
        parts.append(f"published {s['samples_published']} samples")
    if s["samples_received"] is not None:
        parts.append(f"received {s['samples_received']}, dropped {s['samples_dropped']}, "
                     f"missing {s['samples_missing']}; windows fitted {s['windows_fitted']}, "
                     f"skipped {s['windows_skipped']}")
    if s.get("speed_derived") and not (s.get("inputs") or {}).get("problem"):
        parts.append("speed derived from position")
    m, r = s["last_model"], s["last_ridges"]
    if m:
        parts.append(f"last {m['output']} model {len(m['terms'])} terms")
    if r and r.get("h1", {}).get("peaks"):
        parts.append(_h1_text(r))
    if s.get("recorded_messages") is not None and not s.get("record_samples_lost"):
        parts.append(f"recorded {s['recorded_messages']} messages, no sample lost")
    if not s["change_events"]:
        parts.append("0 change event(s)")
    diag = _diagnosis_text(s)
    if diag:
        parts.append(diag)
    line = "; ".join(parts)
    return line if v["status"] == "none" else f"{v['status']}: {line}"
