"""Window-by-window history of a live run, built from the published results.

One row per (output, window): the model fitted on the window (term count, term names, fit
time), the free-run R² and NRMSE of the previous model on this window (the cross-validation
published with it), the change detector's score at this window with its threshold, and the
largest H1 peak of the window's model (frequency, gain). Rows are keyed by the window's
sequence number, so results that arrive separately (model, validation, ridges) meet in one
row whatever their order. Change events are kept beside the rows.

Memory is bounded: beyond ``max_rows`` rows per output every other row is dropped (the
history then covers the whole run at half the resolution; ``stride`` says how many windows
one row stands for), so an hour-long run keeps a picture of the whole hour.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

MAX_ROWS = 2048
MAX_EVENTS = 200
#: what each change-detector feature is, in words
CHANGE_NAMES = {"xval_nrmse": "next-window NRMSE", "fit_nrmse": "fit NRMSE",
                "harmonics_db": "harmonics", "h1_gain_db": "H1 gain",
                "h1_phase_rad": "H1 phase", "term_jaccard": "terms"}


def _float(value: Any) -> float | None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _loads(value: Any) -> Any:
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


class RunHistory:
    """Rows per output, filled from model, validation, ridges and change results."""

    def __init__(self, max_rows: int = MAX_ROWS) -> None:
        if max_rows < 8:
            raise ValueError(f"max_rows must be >= 8, got {max_rows}")
        self.max_rows = max_rows
        self.rows: dict[str, dict[int, dict[str, Any]]] = {}
        self.stride: dict[str, int] = {}
        self.events: list[dict[str, Any]] = []
        self.threshold: float | None = None

    def _row(self, output: str, seq: int, stamp: Any = None) -> dict[str, Any]:
        rows = self.rows.setdefault(output, {})
        stride = self.stride.setdefault(output, 1)
        if seq % stride and seq not in rows:
            return {}  # a window between the kept ones after thinning
        row = rows.get(seq)
        if row is None:
            row = rows[seq] = {"seq": seq}
            if len(rows) > self.max_rows:
                self._thin(output)
                row = rows.get(seq, {})
        t = _float(stamp)
        if row and t is not None and "t" not in row:
            row["t"] = t
        return row

    def _thin(self, output: str) -> None:
        stride = self.stride[output] * 2
        self.stride[output] = stride
        rows = self.rows[output]
        for seq in [s for s in rows if s % stride]:
            del rows[seq]

    def model(self, m: Mapping[str, Any]) -> None:
        """A published model (identify JSON with ``window``, ``output``, ``terms``)."""
        w = m.get("window") or {}
        if "seq" not in w or "output" not in m:
            return
        row = self._row(str(m["output"]), int(w["seq"]), w.get("end_stamp"))
        if not row:
            return
        names = [str(t.get("name")) for t in m.get("terms") or [] if isinstance(t, Mapping)]
        row.update(n_terms=len(names), terms=names, fit_ms=_float(m.get("fit_time_ms")))

    def validation(self, status: Mapping[str, Any]) -> None:
        """A published cross-validation status (``identifier/cross_validation/<output>``)."""
        name = str(status.get("name", ""))
        if "/cross_validation/" not in name:
            return
        v = status.get("values") or {}
        on = _loads(v.get("validated_on")) or {}
        if not isinstance(on, Mapping) or "seq" not in on:
            return
        row = self._row(name.rsplit("/", 1)[-1], int(on["seq"]), on.get("end_stamp"))
        if not row:
            return
        row.update(r2=_float(v.get("r2")), nrmse=_float(v.get("nrmse")),
                   diverged=str(v.get("diverged", "")).lower() == "true")
        if "change_score" in v:
            row.update(change_score=_float(v.get("change_score")),
                       change_state=str(v.get("change_state", "")))
        if _float(v.get("change_threshold")) is not None:
            self.threshold = _float(v.get("change_threshold"))

    def ridges(self, g: Mapping[str, Any]) -> None:
        """A published gfrf JSON: the largest H1 peak of the window's model."""
        w = g.get("window") or {}
        if "seq" not in w or "output" not in g:
            return
        row = self._row(str(g["output"]), int(w["seq"]), w.get("end_stamp"))
        if not row:
            return
        peaks = [p for p in (g.get("h1") or {}).get("peaks") or [] if isinstance(p, Mapping)]
        top = max(peaks, key=lambda p: _float(p.get("gain_db")) or -math.inf, default=None)
        row.update(h1_peak_hz=_float(top.get("freq_hz")) if top else None,
                   h1_peak_db=_float(top.get("gain_db")) if top else None)

    def change(self, status: Mapping[str, Any]) -> None:
        """A published change event status (``identifier/change/<output>``)."""
        v = status.get("values") or {}
        w = _loads(v.get("window")) or {}
        event = {"output": str(status.get("name", "")).rsplit("/", 1)[-1],
                 "seq": w.get("seq") if isinstance(w, Mapping) else None,
                 "t": _float(w.get("end_stamp")) if isinstance(w, Mapping) else None,
                 "reasons": list(_loads(v.get("reasons")) or [])}
        self.events.append(event)
        del self.events[:-MAX_EVENTS]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``outputs`` (rows in window order), ``stride``, ``events``,
        ``change_threshold``."""
        return {"outputs": {o: [rows[s] for s in sorted(rows)] for o, rows in self.rows.items()},
                "stride": dict(self.stride), "events": list(self.events),
                "change_threshold": self.threshold}
