"""Health of the package's nodes on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray).

Each node publishes one status about once a second (``period_s``) on the standard absolute
``/diagnostics`` topic, named ``pmsm_sysid: <namespace> <node>`` (e.g.
``pmsm_sysid: /pmsm identifier``) with ``hardware_id`` = the namespace, so the diagnostic
aggregator can group the package's statuses (``startswith: ['pmsm_sysid:']``) and each
motor's (``contains: ['/axis2']``), and rqt_robot_monitor shows them. Level OK, WARN when
something needs a look (the message says what), ERROR when a node cannot do its job; values
are strings (numbers with their unit in the key: ``input_rate_hz``, ``fit_latency_p50_ms``).

(``diagnostic_updater`` is not installable from PyPI; this is the few lines of it needed.)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from ..topics import DIAGNOSTICS, diagnostic_name

OK, WARN, ERROR = 0, 1, 2
Report = tuple[int, str, dict[str, Any]]


def _text(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if not math.isfinite(value) else f"{value:.6g}"
    if isinstance(value, bool) or value is None:
        return str(value).lower() if value is not None else "none"
    return str(value)


class HealthPublisher:
    """Publishes ``report()`` -> (level, message, values) on /diagnostics every period."""

    def __init__(self, node: Node, kind: str, report: Callable[[], Report],
                 period_s: float = 1.0) -> None:
        self.node, self.report = node, report
        self.name = diagnostic_name(node.get_namespace(), kind)
        self.published = 0
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS, 10)
        self._timer = node.create_timer(period_s, self.publish)

    def status(self) -> DiagnosticStatus:
        level, message, values = self.report()
        return DiagnosticStatus(level=bytes([level]), name=self.name, message=message,
                                hardware_id=self.node.get_namespace(),
                                values=[KeyValue(key=k, value=_text(v))
                                        for k, v in values.items()])

    def publish(self) -> None:
        arr = DiagnosticArray(status=[self.status()])
        arr.header.stamp = self.node.get_clock().now().to_msg()
        self._pub.publish(arr)
        self.published += 1


class Rate:
    """Rate of a growing counter between two reports (per second of wall time)."""

    def __init__(self) -> None:
        self._last: tuple[float, float] | None = None

    def __call__(self, count: float) -> tuple[float, float]:
        """(rate per second, increase) since the previous call (nan, 0 the first time)."""
        now = time.monotonic()
        last, self._last = self._last, (now, count)
        if last is None or now <= last[0]:
            return math.nan, 0.0
        return (count - last[1]) / (now - last[0]), count - last[1]


class IdentifierHealth:
    """The identifier's status: input rate and gaps, windows, validation, change events."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.validations = {"pass": 0, "fail": 0}
        self.change_events = 0
        self._rate, self._skipped, self._failed, self._changes = Rate(), Rate(), Rate(), Rate()

    def note(self, result: Any) -> None:
        """Count one window's results (called where they are published)."""
        for v in result.validations:
            self.validations["pass" if v["pass"] else "fail"] += 1
        self.change_events += len(result.changes)

    def __call__(self) -> Report:
        n = self.node
        st = n.engine.stats
        rate, _ = self._rate(st.samples_received)
        _, skipped = self._skipped(st.windows_skipped)
        _, failed = self._failed(st.windows_failed)
        _, changed = self._changes(self.change_events)
        last_val = {o: v["pass"] for o, v in n.last["validation"].items()}
        problems = []
        if n.stale:
            problems.append(f"input stale ({n.input_age_s() or 0:.1f} s)")
        elif st.samples_received == 0:
            problems.append("no input yet")
        if skipped:
            problems.append(f"{int(skipped)} window(s) skipped (fits slower than the hop)")
        if failed:
            problems.append(f"{int(failed)} window(s) not fitted")
        problems += [f"{o} cross-validation fails" for o, ok in last_val.items() if not ok]
        if changed:
            problems.append(f"{int(changed)} plant change(s) detected")
        level = WARN if problems else OK
        message = "; ".join(problems) if problems else (
            f"ok: {rate:.0f} samples/s, {st.windows_fitted} windows fitted")
        values: dict[str, Any] = {
            "input_rate_hz": rate, "samples_received": st.samples_received,
            "samples_missing": st.samples_missing, "samples_dropped": st.samples_dropped,
            "gaps": st.gaps, "unaligned": st.unaligned, "input_age_s": n.input_age_s(),
            "input_stale": n.stale, "windows_fitted": st.windows_fitted,
            "windows_skipped": st.windows_skipped, "windows_failed": st.windows_failed,
            "fit_latency_p50_ms": st.fit_latency_p50_ms,
            "fit_latency_p99_ms": st.fit_latency_p99_ms,
            "validation_pass": self.validations["pass"],
            "validation_fail": self.validations["fail"],
            "change_events": self.change_events,
            "settings_changes": getattr(n, "settings_changes", 0)}
        values.update({f"validation.{o}": "pass" if ok else "fail" for o, ok in last_val.items()})
        return level, message, values


def gfrf_health(node: Any) -> Callable[[], Report]:
    """The GFRF node's status: models received, analysed, skipped, failed."""
    failed_rate = Rate()

    def report() -> Report:
        s = node.summary()
        _, failed = failed_rate(s["models_failed"])
        level = WARN if failed else OK
        message = (f"{int(failed)} model(s) not analysed" if failed else
                   f"ok: {s['models_analysed']} models analysed")
        values = {k: s[k] for k in ("models_received", "models_skipped", "models_analysed",
                                    "models_failed", "ridges_published")}
        return level, message, values

    return report


def diagnose_health(node: Any) -> Callable[[], Report]:
    """The live diagnosis's status: WARN with the effects while the latest diagnosis finds
    physics the reference lacks, and when a diagnosis failed or spans were skipped."""
    from .. import diagnosed

    rate = Rate()

    def report() -> Report:
        counts, last = node.counts(), node.last
        st = node.engine.stats
        r, _ = rate(st.samples_received)
        lacks = "the plant" if node.plant is not None else "the simulation"
        problems = []
        if last is not None and diagnosed.mismatch(last):
            problems.append(f"missing from {lacks}: {diagnosed.found_text(last)}")
        if node.last_failed:
            problems.append(f"last diagnosis failed: {node.last_failed}")
        skipped = counts["diagnoses_skipped"] - node.skips_before_last
        if skipped:
            problems.append(f"{skipped} span(s) skipped (diagnoses slower than period_s)")
        if st.samples_received == 0:
            problems.append("no input yet")
        fs = node.sample_rate_hz() or 0.0
        if problems:
            message = "; ".join(problems)
        elif last is None:
            have = st.samples_received / fs if fs else 0.0
            message = (f"ok: collecting the first span ({min(have, node.params['span_s']):.0f}"
                       f" of {node.params['span_s']:g} s)")
        else:
            message = (f"ok: nothing missing from {lacks} in the latest span; "
                       f"{counts['diagnoses_run']} diagnoses run")
        before, after = diagnosed.held_out_nrmse(last or {})
        values: dict[str, Any] = {
            **counts, "input_rate_hz": r, "samples_received": st.samples_received,
            "effects": ", ".join(str(e.get("name")) for e in diagnosed.effects(last or {})),
            "last_span_end_s": (last or {}).get("window", {}).get("end_stamp"),
            "force_nrmse_before": before, "force_nrmse_after": after,
            "diagnosis_latency_p50_ms": st.fit_latency_p50_ms,
            "diagnosis_latency_p99_ms": st.fit_latency_p99_ms,
            "reference": node.reference}
        level = WARN if problems else OK
        return level, message, values

    return report


def sim_health(node: Any) -> Callable[[], Report]:
    """The sim motor's status: samples published and their rate."""
    rate = Rate()

    def report() -> Report:
        r, _ = rate(node.published)
        values = {"samples_published": node.published, "publish_rate_hz": r,
                  "sample_rate_hz": node.fs, "clock": node.values["clock"],
                  "finished": node.finished}
        return OK, f"ok: {node.published} samples published", values

    return report


def recorder_health(node: Any) -> Callable[[], Report]:
    """The recorder's status: messages recorded, per topic."""
    rate = Rate()

    def report() -> Report:
        r, _ = rate(node.total)
        values: dict[str, Any] = {"messages_recorded": node.total, "record_rate_hz": r,
                                  "topics_waiting": len(node.pending)}
        values.update({f"messages.{t}": n for t, n in sorted(node.counts.items())})
        return OK, f"ok: {node.total} messages recorded", values

    return report


def replay_health(node: Any) -> Callable[[], Report]:
    """The replayer's status: its phase and the messages published."""
    rate = Rate()

    def report() -> Report:
        total = sum(node.stats.counts.values())
        r, _ = rate(total)
        level = WARN if node.stats.passes and not node.stats.matched else OK
        message = ("no subscriber matched before playing" if level == WARN else
                   f"ok: {total} messages published")
        return level, message, {"messages_published": total, "publish_rate_hz": r,
                                "passes": node.stats.passes, "finished": node.finished}

    return report


def monitor_health(node: Any) -> Callable[[], Report]:
    """What the monitor sees of its pipeline: per input topic the rate, gaps and age."""

    def report() -> Report:
        snap = node.snapshot()
        inputs = [t for t in snap["topics"] if t["topic"].rsplit("/", 1)[-1] in
                  ("thrust", "speed", "position")]
        silent = [t["topic"] for t in inputs if t["count"] and (t["age_s"] or 0.0) > 1.0]
        gaps = sum(t["gaps"] for t in inputs)
        values: dict[str, Any] = {}
        for t in inputs:
            values[f"{t['topic']}.rate_hz"] = t["rate_hz"]
            values[f"{t['topic']}.gaps"] = t["gaps"]
        if silent:
            return WARN, f"no message for over 1 s on {', '.join(silent)}", values
        if not any(t["count"] for t in inputs):
            return WARN, "no input seen yet", values
        return OK, f"ok: inputs arriving, {gaps} gap(s) so far", values

    return report
