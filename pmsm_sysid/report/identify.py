"""Report sections of one identification: signals, model, validation (Sections III-IV of Liu et al.
(2005)).

The identify JSON says which windows and model; the recording gives the series. Predictions and
tests are recomputed here exactly as ``identify`` computes them
(:func:`pmsm_sysid.core.selection.identify.validate_narx`): each window is preceded by the
structure's max lag of samples when the recording has them; the model's max lag L of samples
start the free run (Eq. 12 of Liu et al. 2005) and the one-step-ahead residuals of rows L.. feed
the tests (Eq. 13).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import plots
from ..clocktext import is_wall_clock, time_of_day
from ..core.errors import DataError
from ..core.recording.signals import Recording
from ..core.terms.model import NarxModel
from ..core.validation.correlation import CorrelationTests, correlation_tests, welch_psd
from ..core.validation.prediction import one_step_ahead, simulate
from .html import Block, Facts, Note, Section, Table
from .sink import Sink

FloatArray = NDArray[np.float64]
PSD_SEGMENT = 512  # Welch segment: fs/512 resolution (0.98 Hz at 500 Hz)


@dataclass(frozen=True)
class WindowSeries:
    """One window's samples and the model's predictions over them."""

    window: str
    k: FloatArray          # sample indices of the window itself
    u: FloatArray
    y: FloatArray
    predicted: FloatArray  # model predicted output (Eq. 12) on the window
    osa: FloatArray        # one-step-ahead prediction (Eq. 10) on the window
    residuals: FloatArray  # one-step-ahead residuals of every predicted row (tests)
    u_rows: FloatArray     # the input on those rows


def window_series(rec: Recording, model: NarxModel, rng: tuple[int, int], ext_lag: int,
                  window: str) -> WindowSeries:
    """Predictions of ``model`` on samples ``rng`` of ``rec`` (module docstring)."""
    start, stop = int(rng[0]), int(rng[1])
    if not 0 <= start < stop <= len(rec):
        raise DataError(f"{window} range {start}:{stop} is outside the recording (0:{len(rec)})")
    lo = max(start - ext_lag, 0)
    y = np.asarray(rec.signal(model.output_name)[lo:stop], dtype=np.float64)
    u = np.asarray(rec.signal(model.input_name)[lo:stop], dtype=np.float64)
    lag = model.max_lag
    if len(y) <= lag:
        raise DataError(f"{window} window has {len(y)} samples, the model needs more than {lag}")
    run = simulate(model, u, y[:lag]).y
    osa = one_step_ahead(model, y, u)
    w = slice(start - lo, None)
    return WindowSeries(window=window, k=np.arange(start, stop, dtype=np.float64), u=u[w],
                        y=y[w], predicted=run[w], osa=osa[w], residuals=(y - osa)[lag:],
                        u_rows=u[lag:])


def _num(x: Any, fmt: str = ".4g") -> str:
    return "n/a" if x is None else format(float(x), fmt)


def term_table(d: Mapping[str, Any]) -> Table:
    """Tables 2 and 3 of Liu et al. (2005): term, estimate, standard deviation, ERR."""
    rows = tuple((str(t["name"]), _num(t["estimate"], ".5e"), _num(t.get("std"), ".4e"),
                  _num(t.get("err"), ".6f")) for t in d["terms"])
    total = sum(float(t.get("err") or 0.0) for t in d["terms"])
    return Table(f"Identified model {d.get('input', 'u')} → {d.get('output', 'y')}: "
                 f"{len(rows)} terms, sum of ERR {total:.6f} (as Tables 2, 3 of Liu et al. 2005)",
                 ("Model term", "Estimate", "Std. dev.", "ERR"), rows)


def _stamp(t: float) -> str:
    """A window stamp: UTC clock time for wall-clock stamps, seconds for a simulated clock."""
    return time_of_day(t) if is_wall_clock(t) else f"{t:.2f} s"


def _live_window(w: Mapping[str, Any]) -> str:
    """A live model's window by its stamps (its sample indices count from the clock's
    origin, e.g. 1970 for wall-clock stamps, and mean nothing to a reader)."""
    n = w.get("n_samples")
    where = f"window {w.get('seq', '?')}, {n} samples" if n else f"window {w.get('seq', '?')}"
    a, b = w.get("start_stamp"), w.get("end_stamp")
    if a is None or b is None:
        return where
    utc = " UTC" if is_wall_clock(float(a)) else ""
    return f"{where}, {_stamp(float(a))} to {_stamp(float(b))}{utc}"


def fit_table(d: Mapping[str, Any]) -> Table:
    v = d.get("validation") or {}
    rows = []
    for name in ("estimation", "validation"):
        m = v.get(name)
        rng = d.get("estimate" if name == "estimation" else "validate")
        if m:
            where = f"{rng[0]}:{rng[1]}" if rng else ""
            if name == "estimation" and isinstance(d.get("window"), Mapping):
                where = _live_window(d["window"])
            rows.append((name, where, _num(m.get("nmse")), _num(m.get("r2")),
                         _num(m.get("osa_r2"))))
    return Table("Fit on each window (model predicted output, Eq. 12 of Liu et al. 2005; "
                 "one-step-ahead Eq. 10)", ("window", "samples", "NMSE", "R²", "one-step R²"),
                 tuple(rows))


def correlation_table(tests: Mapping[str, Mapping[str, Any]]) -> Table:
    rows = tuple((name, _num(t.get("max_abs")), _num(t.get("max_allowed")),
                  _num(t.get("band")),
                  f"{t.get('n_outside', 'n/a')}/{t.get('n_lags', 'n/a')}",
                  str(t.get("n_allowed", "n/a")),
                  "pass" if t.get("pass") else "FAIL") for name, t in tests.items())
    return Table("Correlation tests (Eq. 13 of Liu et al. 2005): a test passes when no more "
                 "of its lags fall outside the 95 % band than white residuals put there 199 "
                 "times in 200, and none beyond the limit",
                 ("test", "max |φ|", "limit", "95% band", "lags outside", "allowed",
                  "verdict"), rows)


def model_facts(d: Mapping[str, Any]) -> Facts:
    st = d.get("structure") or {}
    items = [("signals", f"{d.get('input')} → {d.get('output')} at "
                         f"{_num(d.get('sample_rate_hz'), 'g')} Hz"),
             ("structure", f"ny = {st.get('ny')}, nu = {st.get('nu')}, degree "
                           f"{st.get('degree')}, delay {st.get('delay')}, "
                           f"{st.get('n_candidates')} candidates"),
             ("selection", f"{d.get('method', 'n/a')}, criterion {d.get('criterion', 'n/a')}")]
    if d.get("source"):
        items.insert(0, ("recording", str(d["source"])))
    return Facts(tuple(items))


def _corr_lags(d: Mapping[str, Any]) -> int:
    ee = (((d.get("validation") or {}).get("correlation_tests") or {}).get("ee") or {})
    return int(ee.get("n_lags", 20))


def _ext_lag(model: NarxModel) -> int:
    return model.structure.max_lag if model.structure is not None else model.max_lag


def series_sections(d: Mapping[str, Any], model: NarxModel, rec: Recording,
                    sink: Sink) -> list[Section]:
    """Signals and validation sections drawn from the recording."""
    est = window_series(rec, model, tuple(d["estimate"]), _ext_lag(model), "estimation")
    fs = float(rec.sample_rate_hz)
    seg = min(len(est.u), PSD_SEGMENT)
    f, pu = welch_psd(est.u, fs, seg)
    _, py = welch_psd(est.y, fs, seg)
    signals: list[Block] = [
        sink.figure(plots.io_series(est.k, est.u, est.y, model.input_name, model.output_name,
                                    name="io_estimation")),
        sink.figure(plots.psd_pair(f / fs, pu, py, fs, model.input_name, model.output_name)),
    ]
    val_blocks: list[Block] = [sink.figure(plots.predicted_vs_measured(
        est.k, est.y, est.predicted, model.output_name, "estimation",
        name="predicted_estimation"))]
    if d.get("validate"):
        val = window_series(rec, model, tuple(d["validate"]), _ext_lag(model), "validation")
        val_blocks.append(sink.figure(plots.predicted_vs_measured(
            val.k, val.y, val.predicted, model.output_name, "validation",
            name="predicted_validation")))
    val_blocks.append(fit_table(d))
    tests: CorrelationTests = correlation_tests(est.residuals, est.u_rows, _corr_lags(d))
    val_blocks.append(sink.figure(plots.correlation_tests(tests, len(est.residuals))))
    val_blocks.append(correlation_table(tests.to_dict()))
    return [Section("Recording: input and output (Figs. 2, 3, 7, 8 of Liu et al. 2005)",
                    tuple(signals)),
            Section("Validation (Figs. 4-6, 9-11 of Liu et al. 2005)", tuple(val_blocks))]


def json_only_sections(d: Mapping[str, Any], why: str,
                       title: str = "Validation: fit and correlation tests") -> list[Section]:
    """What the identify JSON alone supports: the fit and test tables, and why no series."""
    blocks: list[Block] = [Note(f"time-domain figures not drawn: {why}"), fit_table(d)]
    tests = ((d.get("validation") or {}).get("correlation_tests")) or {}
    if tests:
        blocks.append(correlation_table(tests))
    return [Section(title, tuple(blocks))]


def model_section(d: Mapping[str, Any]) -> Section:
    blocks: list[Block] = [model_facts(d), term_table(d)]
    for w in (d.get("data_check") or {}).get("warnings", []):
        blocks.append(Note(str(w)))
    return Section("Identified NARX model (Tables 2, 3 of Liu et al. 2005)", tuple(blocks))
