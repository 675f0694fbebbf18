"""What ``pmsm-sysid monitor`` shows: one snapshot of the monitor node as rich renderables.

Built for an 80-column terminal (wider ones show the same, with more room): the topics with
rate, gaps and last value in their units; per identified output the latest model as its
top terms by ERR; each validation row (per output: ``next window``, the identifier's
cross-validation of the newest model on the next window; ``own window``, the GFRF node's
check of that model on its estimation window and of its linear part's stability) as
pass/fail with the one reason that matters and what to try, beside the run's count of windows
passed (a failed correlation test in a run that passes as often as a correct model is shown
as chance, ``fail``, not ``FAIL``); the latest change events with their time; the latest
live diagnosis in one line; a hint when nothing arrives at all. Numbers are shown with 3
significant digits.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

from rich import box
from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from ..clocktext import is_wall_clock, time_of_day
from ..core.online.history import CHANGE_NAMES

UNITS = {"thrust": "N", "speed": "m/s", "position": "m"}
TOP_TERMS = 4
EVENTS = 3
# why a correlation test fails, and what to try (Billings-Voon tests of the residual e)
CORR_HINT = {
    "ee": "residual not white: try more lags or terms",
    "ue": "residual follows the input: try more input lags",
    "u2e": "nonlinearity missing: try degree 2 or more terms",
    "u2e2": "nonlinearity missing: try more terms",
    "e_eu": "nonlinear terms missing: try more terms",
}


def num(value: Any, unit: str = "") -> str:
    """``value`` with 3 significant digits and its unit; '-' when absent or not a number."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        return "-"
    if not math.isfinite(x):
        return str(x)
    if unit == "m" and abs(x) < 0.1:
        x, unit = x * 1e3, "mm"
    text = f"{x:.0f}" if abs(x) >= 1000 else f"{x:.3g}"
    return f"{text} {unit}" if unit else text


def fraction(value: Any) -> str:
    """R² and the like: 3 decimals between -1 and 1, 3 significant digits otherwise."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        return "-"
    return f"{x:.3f}" if -1.0 <= x <= 1.0 else num(x)


def _table(title: str) -> Table:
    """A table at least as wide as its title (a narrower one wraps the title mid-phrase)."""
    return Table(title=title, title_justify="left", title_style="bold", box=box.SIMPLE_HEAD,
                 pad_edge=False, show_edge=False, min_width=len(title))


def seconds(value: Any) -> str:
    """A duration in ms below one second, in s above."""
    if value is None:
        return "-"
    s = float(value)
    return f"{s * 1e3:.0f} ms" if s < 1.0 else f"{s:.1f} s"


def clock(stamp_s: Any) -> str:
    """A message time: UTC clock time for wall-clock stamps, seconds for a simulated clock."""
    if stamp_s is None:
        return "-"
    s = float(stamp_s)
    return time_of_day(s, tenths=False) if is_wall_clock(s) else f"t={s:.1f} s"


def _short_topic(topic: str, namespace: str) -> str:
    for prefix in (namespace.rstrip("/") + "/", "/pmsm_sysid/"):
        if topic.startswith(prefix):
            return topic[len(prefix):]
    return topic


def topics_table(snap: Mapping[str, Any]) -> Table:
    t = _table("topics")
    for col, just in (("topic", "left"), ("msgs", "right"), ("rate", "right"),
                      ("gaps", "right"), ("age", "right"), ("last", "right")):
        t.add_column(col, justify=just, no_wrap=True)  # type: ignore[arg-type]
    for s in snap["topics"]:
        name = _short_topic(str(s["topic"]), str(snap["namespace"]))
        last = s["last_value"]
        shown = num(last, UNITS.get(name, "")) if isinstance(last, (int, float)) else ""
        gaps = str(s["gaps"]) + (f" ({s['missing']} lost)" if s["missing"] else "")
        t.add_row(name, str(s["count"]), num(s["rate_hz"], "Hz"), gaps, seconds(s["age_s"]),
                  shown)
    return t


def _fit_of(view: Mapping[str, Any], output: str) -> Mapping[str, Any]:
    """The latest cross-validation status values of ``output`` (identifier first)."""
    for s in view.get("validation") or []:
        if str(s.get("name", "")).endswith(f"/{output}"):
            return s.get("values") or {}
    return {}


def models_table(view: Mapping[str, Any]) -> RenderableType:
    models = view.get("models") or {}
    if not models:
        return Text("model: none yet")
    t = _table("latest models (top terms by ERR)")
    t.add_column("output", no_wrap=True)
    t.add_column("terms", justify="right", no_wrap=True)
    t.add_column("free-run R²", justify="right", no_wrap=True)
    t.add_column("top terms")
    for output, m in models.items():
        terms = sorted(m.get("terms") or [], key=lambda x: -float(x.get("err") or 0.0))
        top = ", ".join(f"{x['name']} {num(x.get('estimate'))}" for x in terms[:TOP_TERMS])
        more = f" +{len(terms) - TOP_TERMS}" if len(terms) > TOP_TERMS else ""
        fit = _fit_of(view, output)
        r2 = fit.get("r2", (m.get("validation") or {}).get("r2"))
        name = f"{output} (derived)" if m.get("speed_derived") else str(output)
        t.add_row(name, str(m.get("n_terms", len(terms))), fraction(r2), top + more)
    return t


def _corr(values: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Correlation tests of a validation status, from either layout of its values."""
    out: dict[str, dict[str, Any]] = {}
    for key, raw in values.items():
        parts = str(key).split(".")
        if parts[0] != "corr" or len(parts) < 2:
            continue
        if len(parts) == 2:
            try:
                out[parts[1]] = dict(json.loads(raw))
            except (TypeError, ValueError):
                continue
        else:
            out.setdefault(parts[1], {})[parts[2]] = raw
    return out


def _run_of(view: Mapping[str, Any], output: str) -> Mapping[str, Any]:
    """The run's windows so far for ``output``, from the identifier's latest status."""
    for s in view.get("validation") or []:
        if str(s.get("name", "")) == f"identifier/cross_validation/{output}":
            return s.get("values") or {}
    return {}


def _chance(run: Mapping[str, Any]) -> bool:
    """The run's windows pass as often as a correct model's (the run summary's test)."""
    return str(run.get("run_consistent", "")).lower() == "true"


def _corr_reason(name: str, c: Mapping[str, Any], run: Mapping[str, Any]) -> str:
    text = f"{name} {num(c.get('max_abs'))} > {num(c.get('band'))}"
    if c.get("n_outside") is not None and c.get("n_allowed") is not None:
        text += f", {c['n_outside']}/{c.get('n_lags', '?')} lags out ({c['n_allowed']} ok)"
    if _chance(run):
        return text + ": by chance, the run passes"
    return f"{text}: {CORR_HINT.get(name, 'residual not white')}"


def reason(status: Mapping[str, Any], run: Mapping[str, Any] | None = None) -> str:
    """The one reason that matters for a validation result, with what to try; a failed
    correlation test of a run whose windows pass as often as a correct model's (``run``:
    the identifier's run values) is said to be chance."""
    v = status.get("values") or {}
    if str(v.get("diverged", "")).lower() == "true":
        return "free run diverged: the model is unstable on new data"
    r2, min_r2 = v.get("r2"), v.get("min_r2")
    if r2 is not None and min_r2 is not None and float(r2) < float(min_r2):
        return f"free-run R² {fraction(r2)} < {fraction(min_r2)}: try more terms or data"
    fails = {k: c for k, c in _corr(v).items() if str(c.get("pass")).lower() == "false"}
    if fails:
        name = max(fails, key=lambda k: float(fails[k].get("max_abs", 0.0))
                   / max(float(fails[k].get("band", 1.0)), 1e-12))
        return _corr_reason(name, fails[name], run or {})
    if str(v.get("stable", "")).lower() == "false":
        return "linear part unstable: try fewer lags or more data"
    if status.get("passed"):
        return f"free-run R² {fraction(r2)}" if r2 is not None else str(status.get("message", ""))
    return str(status.get("message", ""))


#: what each row checks: the identifier's cross-validation of a window's model on the next
#: window; the GFRF node's check of the same model on its own window (fit, correlation
#: tests, stability of the linear part); the identifier's input
CHECKS = {"cross_validation": "next window", "validation": "own window", "input": "input"}


def _label(name: str) -> tuple[str, str]:
    parts = name.split("/")
    if len(parts) == 3:
        return parts[2], CHECKS.get(parts[1], parts[1])
    if len(parts) == 2:
        return parts[0], CHECKS.get(parts[1], parts[1])
    return name, ""


def _window_text(s: Mapping[str, Any], run: Mapping[str, Any]) -> Text:
    if s.get("passed"):
        return Text("pass", style="green")
    if _chance(run) and "by chance" in reason(s, run):
        return Text("fail", style="yellow")
    return Text("FAIL", style="bold red")


def validation_table(view: Mapping[str, Any]) -> RenderableType:
    statuses = view.get("validation")
    if statuses is None:
        return Text("validation: none yet")
    t = _table("validation (run: windows passed; a correct model fails 1 in 20)")
    for col in ("output", "check", "window", "run"):
        t.add_column(col, no_wrap=True)
    t.add_column("reason")
    for s in statuses:
        output, check = _label(str(s.get("name", "")))
        run = _run_of(view, output)
        shown = (f"{run['windows_passed']}/{run['windows_validated']}"
                 if "windows_validated" in run else "")
        t.add_row(output, check, _window_text(s, run), shown, reason(s, run))
    return t


def _change_row(c: Mapping[str, Any]) -> tuple[str, str, str]:
    v = c.get("values") or {}
    try:
        reasons = list(json.loads(v.get("reasons", "[]")))
        z = dict(json.loads(v.get("z", "{}")))
    except (TypeError, ValueError):
        reasons, z = [], {}
    what = ", ".join(CHANGE_NAMES.get(r, r) + (f" z={num(z[r])}" if z.get(r) is not None
                                               else "") for r in reasons[:3])
    output = str(c.get("name", "")).rsplit("/", 1)[-1]
    return clock(c.get("stamp_s")), output, what or str(c.get("message", ""))


def change_scores(view: Mapping[str, Any]) -> str:
    """The change detector's latest score per output against its threshold."""
    parts, threshold = [], None
    for s in view.get("validation") or []:
        v = s.get("values") or {}
        if "change_score" in v:
            parts.append(f"{str(s.get('name', '')).rsplit('/', 1)[-1]} {num(v['change_score'])}")
            threshold = v.get("change_threshold", threshold)
    if not parts:
        return ""
    return "change score " + ", ".join(parts) + (f" (threshold {num(threshold)})"
                                                 if threshold is not None else "")


def changes_block(view: Mapping[str, Any]) -> RenderableType:
    changes = view.get("changes") or []
    scores = change_scores(view)
    if not changes:
        return Text("change events: none" + (f"; {scores}" if scores else ""))
    t = _table(f"change events (latest {min(len(changes), EVENTS)} of {len(changes)})"
               + (f"; {scores}" if scores else ""))
    t.add_column("time", no_wrap=True)
    t.add_column("output", no_wrap=True)
    t.add_column("what changed (z = standardised change)")
    for c in changes[-EVENTS:]:
        t.add_row(*_change_row(c))
    return t


def ridges_line(view: Mapping[str, Any]) -> RenderableType:
    r = view.get("ridges")
    if not r or "error" in r:
        return Text("GFRF: none yet")
    h1 = [float(f) for f in r.get("h1") or [] if f is not None]
    h2 = sorted({round(float(f), 1) for f in r.get("h2") or [] if f is not None})
    text = f"GFRF: H1 peak {num(h1[0], 'Hz') if h1 else '-'}"
    if h2:
        text += ", H2 ridges at " + ", ".join(num(f) for f in h2[:5]) + (
            " ..." if len(h2) > 5 else "") + " Hz"
    if r.get("stable") is False:
        text += " (linear part unstable)"
    return Text(text)


def nothing_received(snap: Mapping[str, Any]) -> str | None:
    """What to check when no message at all arrived (None once one did)."""
    if any(s.get("count") for s in snap["topics"]):
        return None
    domain = os.environ.get("ROS_DOMAIN_ID", "0")
    return (f"nothing received on {snap['namespace']} yet: is a pipeline publishing there "
            f"with ROS_DOMAIN_ID={domain}? (start one: pmsm-sysid run; another namespace: "
            "--namespace)")


WIDTH = 80


def diagnosis_line(view: Mapping[str, Any], width: int = WIDTH) -> Text:
    """The latest live diagnosis in one line of at most ``width`` characters: when (the
    span's end), how many ran and were skipped, what it found missing."""
    from ..diagnosed import found_text, held_out_nrmse, mismatch

    d = view.get("diagnosis")
    if not d or "error" in d:
        return Text("diagnosis: none yet" if not d else "diagnosis: unreadable message")
    counts = d.get("counts") or {}
    head = (f"diagnosis {clock((d.get('window') or {}).get('end_stamp'))}, "
            f"{counts.get('diagnoses_run', '?')} run/{counts.get('diagnoses_skipped', '?')} "
            "skipped: ")
    found = found_text(d)
    if not mismatch(d):
        found += f" (force NRMSE {num(held_out_nrmse(d)[0])})"
    text = head + found
    if len(text) > width and mismatch(d):  # the confidences go first
        text = head + found_text(d, confidence=False)
    if len(text) > width:
        text = text[: width - 3] + "..."
    return Text(text, style="bold yellow" if mismatch(d) else "")


def view(snap: Mapping[str, Any], elapsed_s: float) -> Group:
    """The whole screen of one snapshot."""
    sysid = snap["sysid"]
    head = Text(f"pmsm-sysid monitor  {snap['namespace']}  {elapsed_s:.1f} s", style="bold")
    hint = nothing_received(snap)
    parts: list[RenderableType] = [head]
    if hint:
        parts.append(Text(hint, style="yellow"))
    return Group(*parts, topics_table(snap), models_table(sysid), ridges_line(sysid),
                 validation_table(sysid), changes_block(sysid),
                 diagnosis_line(sysid))
