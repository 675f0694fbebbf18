"""What a diagnosis says, in a control engineer's words: an ``unexplained`` force by where
it acts (positions in mm, speeds in m/s, the end of the stroke named), significances without
``inf``, and where the mismatch lives as shares that add up to at most 100 %."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["significance_text", "unexplained_text", "where_text"]

#: -log10 p beyond which p underflows and only "> 300" is meaningful
CAP = 300.0
#: (scale, unit, format) of the values along each axis of an unexplained curve
SCALES = {"m": (1e3, "mm", ".1f"), "m/s": (1.0, "m/s", ".3g"), "N": (1.0, "N", ".3g"),
          "s": (1.0, "s", ".3g")}
#: share of the travel within which a region counts as at the end of the stroke
END = 0.05


def significance_text(sig: Any) -> str:
    """-log10 p as printed: '>300' where p underflows, 'n/a' when unknown, never -0."""
    try:
        x = float(sig)
    except (TypeError, ValueError):
        return "n/a"
    if math.isnan(x):
        return "n/a"
    return f">{CAP:.0f}" if x >= CAP else f"{x if x > 0 else 0.0:.1f}"


def _at(x: float, unit: str) -> str:
    scale, shown, fmt = SCALES.get(unit, (1.0, unit, ".3g"))
    return f"{x * scale:{fmt}} {shown}".strip()


def _stroke(region: Sequence[float], curve: Mapping[str, Any]) -> str:
    """Where a position region lies on the travel the curve spans."""
    at = [float(a) for a in curve.get("at") or []]
    if len(at) < 2:
        return ""
    lo, hi = min(at), max(at)
    span = hi - lo
    if span <= 0:
        return ""
    if region[1] >= hi - END * span:
        return "at the end of the stroke, "
    if region[0] <= lo + END * span:
        return "at the start of the stroke, "
    return "inside the stroke, "


def unexplained_text(p: Mapping[str, Any]) -> str:
    """An ``unexplained`` entry's parameters in words, e.g. 'an extra force of +3.58 N
    (against the curve's median) at the end of the stroke, x = 240.2-246.3 mm (largest at
    246.3 mm; a smooth curve over position)'."""
    axis = str(p.get("axis", "")).split("_")[0]
    unit = str(p.get("unit", ""))
    if "frequency_hz" in p:
        return (f"a sinusoidal force over time, {float(p['frequency_hz']):.3g} Hz, amplitude "
                f"{float(p.get('amplitude_n', math.nan)):.3g} N")
    region, peak = p.get("region"), p.get("peak_n")
    if not region or peak is None:
        return f"a force over {axis or 'an axis'} that no library effect names"
    lo, hi = (float(x) for x in region)
    kind = "a friction force (x sign of speed)" if "friction" in str(p.get("model", "")) \
        else "an extra force"
    var = {"position": "x", "velocity": "v", "thrust": "thrust"}.get(axis, axis)
    where = _stroke((lo, hi), p.get("curve") or {}) if axis == "position" else ""
    text = (f"{kind} of {float(peak):+.3g} N (against the curve's median) {where}{var} = "
            f"{_at(lo, unit).split()[0]}-{_at(hi, unit)}")
    if p.get("peak_at") is not None:
        text += f" (largest at {_at(float(p['peak_at']), unit)}; a smooth curve over {axis})"
    return text


def where_text(where: Sequence[Any], min_significance: float = 3.0) -> str:
    """'velocity 96 %, time +1 %': the significant axes by what each adds beyond the ones
    before it (``added_share``; ``share`` alone where the entry has none)."""
    rows = []
    for w in where:
        d = w.to_dict() if hasattr(w, "to_dict") else dict(w)
        sig = d.get("significance")
        sig = CAP if sig is None else float(sig)  # null in the JSON: p underflowed (inf)
        if d.get("share") is None or not sig >= min_significance:
            continue
        rows.append((str(d["axis"]), float(d.get("added_share", d["share"]))))
    rows.sort(key=lambda r: -r[1])
    rows = rows[:1] + [r for r in rows[1:] if r[1] >= 0.005]  # nothing that rounds to +0 %
    return ", ".join(f"{a} {'+' if i else ''}{100 * s:.0f} %" for i, (a, s) in enumerate(rows))


def used_lines(method: dict[str, Any]) -> list[str]:
    """'data used: ...' for each recording of which spans were used (none when whole)."""
    out = []
    for key, used in (method.get("data_used") or {}).items():
        if not used.get("whole", True):
            label = "" if key == "recording" else " (held-out recording)"
            out.append(f"data used{label}: {used['text']}")
    return out
