"""Bookkeeping behind ``pmsm-sysid monitor``: rates, gaps and the latest results, no ROS.

A :class:`TopicStats` is fed ``(receive_time_s, stamp_ns, value)`` per message:

- ``rate_hz``: messages per second of receive time over the last ``window_s`` seconds,
  ``(n - 1) / (t_last - t_first)`` over the receive times in the window;
- ``stamp_rate_hz``: 1 / median of the recent header-stamp steps (the publisher's sample
  rate, which differs from ``rate_hz`` when a recording is replayed faster than real time);
- a *gap* is a stamp step larger than 1.5 nominal periods, the nominal period being the median
  of the preceding steps (or ``expected_period_s`` when given); ``missing`` adds up
  ``round(step / period) - 1`` over the gaps; ``backwards`` counts non-increasing stamps.

:class:`SysIdView` keeps the latest model / ridges / validation / change events published by
the identification side and the latest live diagnosis (its span, effects, held-out fit and
counters; plain dicts and JSON text, converted from the messages by the node).
The screen itself is drawn by :mod:`pmsm_sysid.cli.monitor_view`.
"""

from __future__ import annotations

import json
import statistics
from collections import deque
from dataclasses import dataclass, field
from typing import Any

GAP_FACTOR = 1.5
_STEP_HISTORY = 64


@dataclass
class TopicStats:
    """Running statistics of one topic."""

    topic: str
    msgtype: str = ""
    window_s: float = 2.0
    expected_period_s: float | None = None
    count: int = 0
    gaps: int = 0
    missing: int = 0
    backwards: int = 0
    last_value: Any = None
    last_stamp_ns: int | None = None
    last_receive_s: float | None = None
    _recv: deque[float] = field(default_factory=deque, repr=False)
    _steps: deque[int] = field(default_factory=lambda: deque(maxlen=_STEP_HISTORY), repr=False)

    def feed(self, receive_s: float, stamp_ns: int | None = None, value: Any = None) -> None:
        """Account for one message received at ``receive_s`` carrying ``stamp_ns``."""
        self.count += 1
        self.last_value = value
        self.last_receive_s = receive_s
        self._recv.append(receive_s)
        while self._recv and self._recv[0] < receive_s - self.window_s:
            self._recv.popleft()
        if stamp_ns is None:
            return
        if self.last_stamp_ns is not None:
            self._account_step(stamp_ns - self.last_stamp_ns)
        self.last_stamp_ns = stamp_ns

    def _account_step(self, step_ns: int) -> None:
        if step_ns <= 0:
            self.backwards += 1
            return
        period = self.nominal_period_ns()
        if period is not None and step_ns > GAP_FACTOR * period:
            self.gaps += 1
            self.missing += max(round(step_ns / period) - 1, 0)
            return  # a gap is not a sample of the nominal period
        self._steps.append(step_ns)

    def nominal_period_ns(self) -> float | None:
        """The expected stamp step: ``expected_period_s`` or the median of recent steps."""
        if self.expected_period_s is not None:
            return self.expected_period_s * 1e9
        if len(self._steps) < 3:
            return None
        return float(statistics.median(self._steps))

    def rate_hz(self, now_s: float | None = None) -> float:
        """Receive rate over the window ending at ``now_s`` (default: the last message)."""
        if now_s is not None:
            while self._recv and self._recv[0] < now_s - self.window_s:
                self._recv.popleft()
        if len(self._recv) < 2:
            return 0.0
        span = self._recv[-1] - self._recv[0]
        return (len(self._recv) - 1) / span if span > 0 else 0.0

    def stamp_rate_hz(self) -> float | None:
        """1 / nominal stamp period, or None before three regular steps were seen."""
        if len(self._steps) < 3:
            return None
        return 1e9 / float(statistics.median(self._steps))

    def snapshot(self, now_s: float | None = None) -> dict[str, Any]:
        """JSON-ready view of the statistics."""
        age = None
        if now_s is not None and self.last_receive_s is not None:
            age = max(now_s - self.last_receive_s, 0.0)
        return {
            "topic": self.topic, "type": self.msgtype, "count": self.count,
            "rate_hz": self.rate_hz(now_s), "stamp_rate_hz": self.stamp_rate_hz(),
            "last_value": self.last_value,
            "last_stamp_s": None if self.last_stamp_ns is None else self.last_stamp_ns / 1e9,
            "age_s": age, "gaps": self.gaps, "missing": self.missing,
            "backwards": self.backwards,
        }


def _parse_json(text: str) -> dict[str, Any] | None:
    try:
        obj = json.loads(text)
    except ValueError:
        return None
    return obj if isinstance(obj, dict) else None


@dataclass
class SysIdView:
    """Latest results of the identification side; each stays None until one arrives."""

    max_events: int = 10
    model: dict[str, Any] | None = None
    models: dict[str, dict[str, Any]] = field(default_factory=dict)
    ridges: dict[str, Any] | None = None
    ridge_frequencies: list[float] | None = None
    validation: list[dict[str, Any]] | None = None
    changes: list[dict[str, Any]] = field(default_factory=list)
    diagnosis: dict[str, Any] | None = None

    def on_model(self, text: str) -> None:
        """A model message (identify JSON): keep terms and fit, the latest one per output."""
        obj = _parse_json(text)
        if obj is None:
            self.model = {"error": "not JSON"}
            return
        terms = [
            {"name": str(t.get("name", "?")), "estimate": t.get("estimate"), "err": t.get("err")}
            for t in obj.get("terms", []) if isinstance(t, dict)
        ]
        val = obj.get("validation", {})
        fit = val.get("validation", {}) if isinstance(val, dict) else {}
        self.model = {"output": obj.get("output"), "n_terms": len(terms), "terms": terms,
                      "validation": fit if isinstance(fit, dict) else {},
                      "speed_derived": bool(obj.get("speed_derived"))}
        self.models[str(obj.get("output"))] = self.model

    def on_ridges(self, text: str) -> None:
        """A ridges message (gfrf JSON): keep the H1 peaks and H2/H3 ridge frequencies."""
        obj = _parse_json(text)
        if obj is None:
            self.ridges = {"error": "not JSON"}
            return
        out: dict[str, Any] = {"stable": obj.get("stable")}
        for key, inner in (("h1", "peaks"), ("h2", "ridges"), ("h3", "ridges")):
            block = obj.get(key, {})
            items = block.get(inner, []) if isinstance(block, dict) else []
            out[key] = [i.get("freq_hz") for i in items if isinstance(i, dict)]
        self.ridges = out

    def on_ridge_frequencies(self, values: list[float]) -> None:
        self.ridge_frequencies = [float(v) for v in values]

    def on_validation(self, statuses: list[dict[str, Any]]) -> None:
        """A validation DiagnosticArray as dicts (name, level, message, values); a status
        replaces the previous one of the same name (several nodes publish validations)."""
        merged = {str(s.get("name", "")): s for s in self.validation or []}
        for s in statuses:
            merged[str(s.get("name", ""))] = dict(s, passed=int(s.get("level", 0)) == 0)
        self.validation = list(merged.values())

    def on_change(self, stamp_s: float | None, statuses: list[dict[str, Any]]) -> None:
        """A change DiagnosticArray: append one event per status, keep the latest few."""
        for s in statuses:
            self.changes.append(dict(s, stamp_s=stamp_s))
        del self.changes[:-self.max_events]

    def on_diagnosis(self, text: str) -> None:
        """A diagnosis message (diagnose JSON of one span): keep its span, effects (name,
        params, confidence), held-out fit, reference and counters."""
        obj = _parse_json(text)
        if obj is None:
            self.diagnosis = {"error": "not JSON"}
            return
        def brief(key: str) -> list[dict[str, Any]]:
            return [{k: e.get(k) for k in ("name", "params", "confidence")}
                    for e in obj.get(key) or [] if isinstance(e, dict)]

        fit = (obj.get("fit") or {}).get("validation") or {}
        self.diagnosis = {"window": obj.get("window"), "effects": brief("effects"),
                          "sim_only": brief("sim_only"),
                          "fit": {"validation": {k: fit.get(k) for k in
                                                 ("nrmse_before", "nrmse_after")}},
                          "reference": obj.get("reference"), "counts": obj.get("counts")}

    def snapshot(self) -> dict[str, Any]:
        return {"model": self.model, "models": dict(self.models), "ridges": self.ridges,
                "ridge_frequencies": self.ridge_frequencies,
                "validation": self.validation, "changes": list(self.changes),
                "diagnosis": self.diagnosis}
