"""One identified model in the frequency domain: the content of the gfrf JSON.

:func:`analyse` maps a :class:`NarxModel` to its GFRFs (core/gfrf), finds H1 peaks and H2/H3
ridges (core/ridges), reports the poles of the linear part with a stability flag (an unstable
linear part is reported and still analysed), and marks each peak and ridge as supported or
not by the estimation data's excitation (core/identifiability), when the model carries that
summary. ``supported`` is null when there is no summary to check against.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..errors import GfrfError
from ..selection.identifiability import ExcitationSummary, identifiability_block, judge
from ..terms.model import NarxModel
from .gfrf import MAX_GRID, Gfrf
from .ridges import Peak, Ridge, h1_peaks, h2_ridges, h3_ridges, is_zero

MAX_AT_POINTS = 10_000
MAX_REPORT_GRID = 512  # --grid N puts N x N dB values in the JSON: keep files reasonable
WEAK_ERR = 1e-3  # nonlinear terms explaining less output variance: "weak" ridges


@dataclass(frozen=True)
class GfrfAnalysis:
    """Result of :func:`analyse`; :meth:`to_dict` is the gfrf JSON.

    Example:
        >>> import pmsm_sysid as ps
        >>> res = ps.gfrf(ps.identify("bags/paper_speed_nominal"))
        >>> res.stable, round(res.peaks[0]["freq_hz"], 1)
        (True, 16.5)
    """

    sample_rate_hz: float
    stable: bool
    poles: tuple[tuple[float, float], ...]
    peaks: tuple[dict[str, Any], ...]
    h2: dict[str, Any]
    h3: dict[str, Any]
    identifiability: dict[str, Any]
    evals: tuple[dict[str, Any], ...] = ()
    grid: dict[str, Any] | None = None
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    model_info: dict[str, Any] = field(default_factory=dict)
    timing_ms: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        radius = max((float(np.hypot(*p)) for p in self.poles), default=0.0)
        out: dict[str, Any] = {
            "sample_rate_hz": self.sample_rate_hz,
            "stable": self.stable,
            "poles": [list(p) for p in self.poles],
            "max_pole_radius": radius,
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "model": dict(self.model_info),
            "h1": {"peaks": list(self.peaks)},
            "h2": dict(self.h2),
            "h3": dict(self.h3),
            "identifiability": dict(self.identifiability),
            "eval": list(self.evals),
            "timing_ms": dict(self.timing_ms),
        }
        if self.grid is not None:
            out["grid"] = self.grid
        safe: dict[str, Any] = json_safe(out)
        return safe


def json_safe(obj: Any) -> Any:
    """Plain Python values with non-finite floats as None (strict JSON: NaN/Inf -> null)."""
    if type(obj) is float:  # most values: math.isfinite (a model's JSON: 0.20 -> 0.12 ms)
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


def excitation_of(model_json: Mapping[str, Any]) -> ExcitationSummary | None:
    """The identify JSON's ``excitation`` summary, if present (DataError if malformed)."""
    ex = model_json.get("excitation")
    return ExcitationSummary.from_dict(ex) if ex else None


def _judged(row: dict[str, Any], freq_hz: float, ex: ExcitationSummary | None) -> dict[str, Any]:
    j = judge(freq_hz, ex)
    row["supported"] = j.supported if ex is not None else None
    row["note"] = j.note
    return row


def _peak_row(p: Peak, ex: ExcitationSummary | None) -> dict[str, Any]:
    return _judged(asdict(p), p.freq_hz, ex)


def _ridge_row(r: Ridge, ex: ExcitationSummary | None) -> dict[str, Any]:
    row = asdict(r)
    row.pop("order")
    row["gain_db"] = r.level_db  # a ridge's gain: median 20 log10 |H_n| along its line
    return _judged(row, r.freq_hz, ex)


def _evals(g: Gfrf, at: Sequence[Sequence[float]]) -> tuple[dict[str, Any], ...]:
    if len(at) > MAX_AT_POINTS:
        raise GfrfError(f"too many --at points ({len(at)} > {MAX_AT_POINTS})")
    rows = []
    for pt in at:
        h = complex(g.h(*[float(x) for x in pt]))
        finite = bool(np.isfinite(h))
        rows.append({
            "f": [float(x) for x in pt], "order": len(pt), "h": [h.real, h.imag],
            "gain_db": float(20 * np.log10(abs(h))) if finite and h != 0 else None,
            "phase_deg": float(np.degrees(np.angle(h))) if finite else None,
        })
    return tuple(rows)


def _grid(g: Gfrf, n: int) -> dict[str, Any]:
    if not 2 <= n <= MAX_REPORT_GRID:
        raise GfrfError(f"--grid must be 2..{MAX_REPORT_GRID} points per axis (got {n}; "
                        f"the engine itself allows {MAX_GRID})")

    def db(h: Any) -> Any:
        return np.round(20 * np.log10(np.maximum(np.abs(h), 1e-300)), 3).tolist()

    f1, h1 = g.h1_curve(n)
    f, h2 = g.h2_grid(n)
    _, h3 = g.h3_slice(n)
    return {"n": n, "h1_f_norm": f1.tolist(), "h1_db": db(h1), "f_norm": f.tolist(),
            "h2_db": db(h2), "h3_slice_db": db(h3), "h3_slice": "H3(f1, f2, f1): rows f1"}


def nonlinear_err(model: NarxModel) -> float | None:
    """Sum of the ERR (Eq. 4 of Liu et al. 2005) of the terms of degree >= 2: the share of the
    output variance the nonlinear terms explain; None when the model carries no ERR values."""
    errs = [float(e) for t, e in zip(model.terms, model.err, strict=True) if t.degree > 1]
    if not errs:
        return 0.0
    return float(sum(errs)) if all(np.isfinite(errs)) else None


def _higher(g: Gfrf, order: int, ridges: list[Ridge], ex: ExcitationSummary | None,
            zero_note: str, nl_err: float | None) -> dict[str, Any]:
    rows = [_ridge_row(r, ex) for r in ridges]
    zero = not ridges and is_zero(g, order)
    out: dict[str, Any] = {"zero": zero, "ridges": rows}
    if order == 3:
        out["slice"] = "f1 = f3"
    if zero:
        out["note"] = zero_note
    elif nl_err is not None and nl_err < WEAK_ERR:
        out["note"] = (f"the nonlinear terms explain {100 * nl_err:.2g}% of the output "
                       f"variance (sum of their ERR < {100 * WEAK_ERR:g}%): these ridges "
                       "describe a weak nonlinearity at this excitation level; whether it is "
                       "the plant's or fitted noise needs checking on independent data")
    out["weak"] = bool(zero or (nl_err is not None and nl_err < WEAK_ERR))
    return out


def _warnings(g: Gfrf, stable: bool, model: NarxModel, ex: ExcitationSummary | None) -> list[str]:
    out = []
    if not stable:
        r = float(np.max(np.abs(g.poles())))
        out.append(f"linear part is unstable (largest pole radius {r:.4f} >= 1): the GFRFs "
                   "are computed but describe no steady state; the model's free run diverges")
    if g.is_linear:
        out.append("model has no nonlinear terms: H2 = H3 = 0")
    if ex is not None and not ex.broadband:
        out.append("estimation input: " + ex.describe() + "; peaks and ridges at "
                   "or between the tones rest on the excitation, not on the plant")
    return out


def _notes(model: NarxModel) -> list[str]:
    """What a reader needs to know that is no fault of the model (identify's models hold a
    constant term by default: a warning about it would be on every default analysis)."""
    if any(t.is_constant for t in model.terms):
        return ["the constant term does not enter the GFRFs (it shifts the operating point)"]
    return []


def analyse(model: NarxModel, excitation: ExcitationSummary | None = None,
            at: Sequence[Sequence[float]] = (), grid: int | None = None,
            orders: Sequence[int] = (1, 2, 3)) -> GfrfAnalysis:
    """GFRFs, peaks, ridges, poles and their support for one model (module docstring)."""
    t0 = time.perf_counter()
    g = Gfrf.from_model(model)
    timing: dict[str, float] = {}
    pls = g.poles()
    stable = bool(np.all(np.abs(pls) < 1.0))
    peaks = h1_peaks(g) if 1 in orders else []
    timing["h1"] = 1e3 * (time.perf_counter() - t0)
    r2 = h2_ridges(g) if 2 in orders else []
    timing["h2"] = 1e3 * (time.perf_counter() - t0) - timing["h1"]
    t3 = time.perf_counter()
    peak_norm = tuple(p.freq_norm for p in peaks)
    r3 = h3_ridges(g, h1_peak_norm=peak_norm) if 3 in orders else []
    timing["h3"] = 1e3 * (time.perf_counter() - t3)
    evals = _evals(g, at)
    grid_out = _grid(g, grid) if grid is not None else None
    timing["total"] = 1e3 * (time.perf_counter() - t0)
    nl = nonlinear_err(model)
    return GfrfAnalysis(
        sample_rate_hz=g.sample_rate_hz, stable=stable,
        poles=tuple((float(p.real), float(p.imag)) for p in pls),
        peaks=tuple(_peak_row(p, excitation) for p in peaks),
        h2=_higher(g, 2, r2, excitation, "H2 = 0: the model has no term of degree >= 2", nl)
        if 2 in orders else {"ridges": [], "skipped": True},
        h3=_higher(g, 3, r3, excitation, "H3 = 0: no term of the model reaches third order", nl)
        if 3 in orders else {"ridges": [], "skipped": True},
        identifiability=identifiability_block(excitation),
        evals=evals, grid=grid_out,
        warnings=tuple(_warnings(g, stable, model, excitation)), notes=tuple(_notes(model)),
        model_info={"input": model.input_name, "output": model.output_name,
                    "n_terms": len(model.terms),
                    "nonlinear_terms": [t.name for t in model.terms if t.degree > 1],
                    "nonlinear_err": nl},
        timing_ms=timing,
    )


def analyse_json(model_json: Mapping[str, Any], **kw: Any) -> GfrfAnalysis:
    """:func:`analyse` on an identify JSON, reading its ``excitation`` summary if present."""
    model = NarxModel.from_dict(model_json)
    return analyse(model, excitation_of(model_json), **kw)
