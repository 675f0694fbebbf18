"""Wire layouts of the GFRF node's outputs (pure Python; the rclpy builders import lazily).

* ``<ns>/ridges`` (std_msgs/String): the gfrf JSON of one model plus
  ``model_id``, ``output``, ``window`` and ``analysis_time_ms``.
* ``<ns>/ridge_frequencies`` (std_msgs/Float64MultiArray): one row per H1 peak and
  H2/H3 ridge, ``RIDGE_FIELDS`` columns, row-major; ``layout.dim[0]`` is the rows
  (label ``"ridges"``), ``layout.dim[1]`` the columns, its label naming them and the codes
  (``KIND_CODES``; supported: 1 yes, 0 no, -1 not checked).
* ``<ns>/validation`` (diagnostic_msgs/DiagnosticArray): one status per model,
  ``gfrf/validation/<output>``, hardware_id = model id, key/values nmse, r2, osa_r2 (free
  run on the estimation window, Eq. 12 of Liu et al. (2005); osa = one step ahead, Eq. 10), the
  same with a
  ``validation.`` prefix when an independent window was used, and ``corr.<test>.max_abs``,
  ``.band``, ``.pass`` for the five correlation tests (Eq. 13); plus ``stable``. Level OK when
  every correlation test passes, the free run did not diverge and the linear part is stable;
  WARN otherwise (the message says why).
"""

from __future__ import annotations

import json
import math
from typing import Any

RIDGE_FIELDS = ("order", "kind", "sign", "freq_hz", "freq_norm", "gain_db", "supported")
KIND_CODES = ("resonance", "dc", "nyquist", "f1", "f2", "f1+f2", "f1+f3", "f1+f2+f3")
COLUMNS_LABEL = (",".join(RIDGE_FIELDS) + "; kind: "
                 + " ".join(f"{i}={k}" for i, k in enumerate(KIND_CODES))
                 + "; supported: 1 yes 0 no -1 unchecked; gain_db of a ridge = its level")
CORRELATION_TESTS = ("ee", "ue", "u2e", "u2e2", "e_eu")
OK, WARN, ERROR = 0, 1, 2


def _num(value: Any) -> float:
    return math.nan if value is None else float(value)


def _supported(value: Any) -> float:
    return -1.0 if value is None else 1.0 if value else 0.0


def ridge_rows(gfrf: dict[str, Any]) -> list[list[float]]:
    """The rows of the ridge array (see the module docstring) from a gfrf JSON."""
    rows = []
    for p in gfrf["h1"]["peaks"]:
        rows.append([1.0, float(KIND_CODES.index(p["kind"])), 1.0, p["freq_hz"], p["freq_norm"],
                     _num(p["gain_db"]), _supported(p.get("supported"))])
    for order in (2, 3):
        for r in gfrf[f"h{order}"]["ridges"]:
            rows.append([float(order), float(KIND_CODES.index(r["kind"])), float(r["sign"]),
                         r["freq_hz"], r["freq_norm"], _num(r["level_db"]),
                         _supported(r.get("supported"))])
    return [[float(x) for x in row] for row in rows]


def rows_from_flat(data: list[float], n_cols: int = len(RIDGE_FIELDS)) -> list[dict[str, Any]]:
    """Inverse of the array layout: one dict per row (for readers and tests)."""
    out = []
    for i in range(0, len(data), n_cols):
        row: dict[str, Any] = dict(zip(RIDGE_FIELDS, data[i:i + n_cols], strict=True))
        row["order"] = int(row["order"])
        row["kind"] = KIND_CODES[int(row["kind"])]
        row["sign"] = int(row["sign"])
        out.append(row)
    return out


def _fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return json.dumps(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else json.dumps(None)
    return str(v)


def validation_values(model: dict[str, Any], gfrf: dict[str, Any] | None = None
                      ) -> tuple[int, str, dict[str, str]]:
    """(level, message, key/values) of the validation status of one model JSON."""
    val = model.get("validation") or {}
    values: dict[str, str] = {}
    reasons: list[str] = []
    est = val.get("estimation") or {}
    for key in ("nmse", "r2", "osa_r2"):
        if key in est:
            values[key] = _fmt(est[key])
    for key, v in (val.get("validation") or {}).items():
        if key in ("nmse", "r2", "osa_r2"):
            values[f"validation.{key}"] = _fmt(v)
    tests = val.get("correlation_tests") or {}
    for name in CORRELATION_TESTS:
        t = tests.get(name)
        if t is None:
            continue
        for k in ("max_abs", "band", "pass"):
            if k in t:
                values[f"corr.{name}.{k}"] = _fmt(t[k])
        if not t.get("pass", False):
            reasons.append(f"correlation test {name} fails")
    if not val:
        reasons.append("no validation statistics in the model message")
    elif not tests:
        reasons.append("no correlation tests in the model message")
    if val.get("free_run_diverged"):
        reasons.append("free-run prediction diverged")
    if gfrf is not None:
        values["stable"] = _fmt(bool(gfrf["stable"]))
        if not gfrf["stable"]:
            reasons.append("linear part unstable")
    level = WARN if reasons else OK
    head = f"r2 {values.get('r2', 'n/a')}, osa_r2 {values.get('osa_r2', 'n/a')}"
    msg = f"{'ok' if level == OK else 'warn'}: {head}" + (f"; {'; '.join(reasons)}"
                                                           if reasons else "")
    return level, msg, values


def ridges_message(gfrf: dict[str, Any]) -> Any:
    """std_msgs/Float64MultiArray of the ridge rows (layout in the dim labels)."""
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

    rows = ridge_rows(gfrf)
    n, m = len(rows), len(RIDGE_FIELDS)
    layout = MultiArrayLayout(dim=[
        MultiArrayDimension(label="ridges", size=n, stride=n * m),
        MultiArrayDimension(label=COLUMNS_LABEL, size=m, stride=m)], data_offset=0)
    return Float64MultiArray(layout=layout, data=[x for row in rows for x in row])


def validation_message(model: dict[str, Any], gfrf: dict[str, Any] | None,
                       stamp: Any = None) -> Any:
    """diagnostic_msgs/DiagnosticArray with one status for this model."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    level, msg, values = validation_values(model, gfrf)
    st = DiagnosticStatus(
        level=bytes([level]), name=f"gfrf/validation/{model.get('output', 'model')}",
        message=msg, hardware_id=str(model.get("model_id", "")),
        values=[KeyValue(key=k, value=v) for k, v in values.items()])
    arr = DiagnosticArray(status=[st])
    if stamp is not None:
        arr.header.stamp = stamp
    return arr
