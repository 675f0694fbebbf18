"""The verdict of a ``pmsm-sysid run`` summary, and its one-line form.

Status ``pass``: every identified output's latest model passed its cross-validation, no fit
failed, no data-check warning on the latest models, no change event, nothing dropped or
skipped. ``FAIL``: a fit failed, the recording lost samples, or an output's latest
cross-validation failed in a way a correct model does not: its free run diverged or fell
below ``min_r2``, or its correlation tests failed and so did more of the run's windows than
chance explains (the tests reject a correct model in about 1 window in 20: more failures
than the 99 % point of Binomial(windows, 0.05)). The line names the output and the test or
reason. ``warning``: everything else that is not a pass, named (a latest window that failed
a correlation test within that chance, data-check warnings, change events, dropped samples,
skipped windows, an input problem, an output not validated yet).
"""

from __future__ import annotations

import math
from typing import Any


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


#: share of windows in which the correlation tests reject a correct model (validation.py)
CHANCE_FAIL = 0.05


def _by_chance(v: dict[str, Any], count: list[int] | None) -> bool:
    """Could this failed validation be the tests' chance rejection of a correct model?"""
    fr = v["free_run"]
    if fr.get("diverged") or fr.get("r2") is None or fr["r2"] < v["min_r2"] or not count:
        return False
    from scipy.stats import binom

    passed, made = count
    return made - passed <= int(binom.ppf(0.99, made, CHANCE_FAIL))


def _output_text(name: str, v: dict[str, Any] | None, count: list[int] | None) -> str:
    if v is None:
        return f"{name} not validated yet"
    fr = v["free_run"]
    tests = v["correlation_tests"]
    n_pass = sum(bool(t["pass"]) for t in tests.values())
    r2 = "n/a" if fr.get("r2") is None else f"{fr['r2']:.4f}"
    runs = f", {count[0]}/{count[1]} windows passed" if count else ""
    if v["pass"]:
        return (f"{name} validation pass (free-run R2 {r2}, correlation tests "
                f"{n_pass}/{len(tests)}{runs})")
    if _by_chance(v, count):
        return (f"{name} latest validation failed: {_failure(v)} (free-run R2 {r2}{runs}: "
                f"within the 1 in 20 windows where the tests reject a correct model)")
    return f"{name} validation FAIL: {_failure(v)} (free-run R2 {r2}{runs})"


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
    "warnings": [...], "outputs": [...]}`` of a run summary (see the module doc; "none":
    nothing identified in this process, e.g. ``--nodes sim``)."""
    vals = s.get("last_validations") or {}
    models = s.get("last_models") or {}
    counts = s.get("validation_counts") or {}
    names = list(dict.fromkeys([*models, *vals]))
    failures: list[str] = []
    warnings: list[str] = []
    outputs: list[str] = []
    for name in names:
        v = vals.get(name)
        text = _output_text(name, v, counts.get(name))
        outputs.append(text)
        if v is None:
            warnings.append(text)
        elif not v["pass"]:
            (warnings if _by_chance(v, counts.get(name)) else failures).append(text)
        check = _data_check(name, models.get(name))
        if check:
            warnings.append(check)
    errors = s.get("errors") or []
    if errors:
        failures.append(f"{len(errors)} fit error(s), last: {errors[-1]}")
    changes = s.get("change_events") or []
    if changes:
        where = ", ".join(f"{c['output']} at {c['window']['end_stamp']:.2f} s "
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
    if not names and s.get("samples_received") is not None:
        warnings.append("no model fitted yet")
    if not names and not failures and not warnings:  # no identifier in this process
        status = "none"
    else:
        status = "FAIL" if failures else "warning" if warnings else "pass"
    return {"status": status, "failures": failures, "warnings": warnings, "outputs": outputs}


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
    line = "; ".join(parts)
    return line if v["status"] == "none" else f"{v['status']}: {line}"
