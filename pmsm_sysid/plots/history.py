"""Figures of a live run over time, window by window, from the run summary's ``history``.

=======================  ====================================================================
function                 shows
=======================  ====================================================================
``fit_over_time``        free-run R² and NRMSE of each output on the window after its fit
``terms_over_time``      term count of each output, and which terms come and go (one row
                         per term, a mark where the window's model holds it)
``h1_over_time``         frequency and gain of the largest H1 peak of each window's model
``change_over_time``     the change detector's score with its threshold, and the events
``latency_over_time``    fit time of each window, and the windows skipped
``diagnosis_over_time``  the live diagnosis span by span: the held-out force NRMSE before and
                         after the effects it names, and each named effect's numbers
=======================  ====================================================================

Time is seconds since the first window of the run (the end of each window or span).
``data`` holds what was drawn, per output (per effect number for the diagnosis).
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .base import Plot, new_figure, styled

MAX_TERM_ROWS = 24
XLABEL = "time since the first window (s)"


def _t0(hist: Mapping[str, Any]) -> float:
    ts = [r["t"] for rows in hist["outputs"].values() for r in rows if r.get("t") is not None]
    ts += [r["t"] for r in (hist.get("diagnosis") or {}).get("rows") or []
           if r.get("t") is not None]
    return min(ts) if ts else 0.0


def _series(rows: Sequence[Mapping[str, Any]], key: str, t0: float) -> tuple[Any, Any]:
    """(t, values) of the rows holding ``key`` (None values left out)."""
    pts = [(float(r["t"]) - t0, float(r[key])) for r in rows
           if r.get("t") is not None and r.get(key) is not None]
    if not pts:
        return np.zeros(0), np.zeros(0)
    t, v = zip(*pts, strict=True)
    return np.asarray(t), np.asarray(v)


def _lines(ax: Any, hist: Mapping[str, Any], key: str, t0: float, style: str = ".-",
           scale: float = 1.0) -> dict[str, Any]:
    drawn = {}
    for output, rows in hist["outputs"].items():
        t, v = _series(rows, key, t0)
        (line,) = ax.plot(t, v * scale, style, markersize=3, label=output)
        drawn[output] = {"t": np.asarray(line.get_xdata()), "v": np.asarray(line.get_ydata())}
    if drawn:
        ax.legend(loc="best")
    return drawn


def _panel(hist: Mapping[str, Any], key: str, ylabel: str) -> tuple[Any, Any, float, Any]:
    """One 8 x 3 in panel of ``key`` per output over time: (figure, axes, t0, lines drawn)."""
    t0 = _t0(hist)
    fig = new_figure(8.0, 3.0)
    ax = fig.subplots()
    drawn = _lines(ax, hist, key, t0)
    ax.set_ylabel(ylabel)
    ax.set_xlabel(XLABEL)
    return fig, ax, t0, drawn


@styled
def fit_over_time(hist: Mapping[str, Any]) -> Plot:
    t0 = _t0(hist)
    fig = new_figure(8.0, 4.4)
    ax_r, ax_n = fig.subplots(2, 1, sharex=True)
    r2 = _lines(ax_r, hist, "r2", t0)
    nrmse = _lines(ax_n, hist, "nrmse", t0)
    ax_r.set_ylabel("free-run R²")
    ax_n.set_ylabel("free-run NRMSE")
    if any(len(d["v"]) and np.all(d["v"] > 0) for d in nrmse.values()):
        ax_n.set_yscale("log")
    ax_n.set_xlabel(XLABEL)
    ax_r.set_title("each model run free on the window after the one it was fitted on")
    return Plot(fig, "run_fit", "Free-run R² and NRMSE of each output's model on the next "
                "window (cross-validation), window by window.", {"r2": r2, "nrmse": nrmse})


def _presence(rows: Sequence[Mapping[str, Any]], t0: float) -> tuple[list[str], Any, Any]:
    """The most frequent terms and a (term, window) presence matrix with window times."""
    rows = [r for r in rows if r.get("terms") is not None and r.get("t") is not None]
    counts = Counter(name for r in rows for name in r["terms"])
    names = [n for n, _ in counts.most_common(MAX_TERM_ROWS)]
    t = np.asarray([float(r["t"]) - t0 for r in rows])
    held = np.asarray([[n in r["terms"] for r in rows] for n in names], dtype=bool)
    return names, t, held.reshape(len(names), len(rows))


@styled
def terms_over_time(hist: Mapping[str, Any]) -> Plot:
    t0 = _t0(hist)
    outputs = list(hist["outputs"])
    fig = new_figure(8.0, 2.2 + 2.6 * len(outputs))
    axes = np.atleast_1d(fig.subplots(1 + len(outputs), 1, sharex=True, squeeze=False)[:, 0])
    counts = _lines(axes[0], hist, "n_terms", t0, ".-")
    axes[0].set_ylabel("terms")
    axes[0].set_title("term count of each window's model")
    data: dict[str, Any] = {"n_terms": counts, "terms": {}}
    for ax, output in zip(axes[1:], outputs, strict=True):
        names, t, held = _presence(hist["outputs"][output], t0)
        for i in range(len(names)):
            ax.plot(t[held[i]], np.full(int(held[i].sum()), i), "|", color="k", markersize=5)
        ax.set_yticks(range(len(names)), names, fontsize=6)
        ax.set_ylim(len(names) - 0.5, -0.5)
        ax.set_title(f"{output}: terms held by each window's model (most frequent first)")
        data["terms"][output] = {"names": names, "t": t, "held": held}
    axes[-1].set_xlabel(XLABEL)
    return Plot(fig, "run_terms", "Term count of each output's model per window, and which "
                "terms come and go (a mark where the window's model holds the term).", data)


@styled
def h1_over_time(hist: Mapping[str, Any]) -> Plot:
    t0 = _t0(hist)
    fig = new_figure(8.0, 4.4)
    ax_f, ax_g = fig.subplots(2, 1, sharex=True)
    freq = _lines(ax_f, hist, "h1_peak_hz", t0, ".")
    gain = _lines(ax_g, hist, "h1_peak_db", t0, ".")
    ax_f.set_ylabel("H1 peak (Hz)")
    ax_g.set_ylabel("H1 peak gain (dB)")
    ax_g.set_xlabel(XLABEL)
    ax_f.set_title("largest peak of the first-order GFRF H1 of each window's model")
    return Plot(fig, "run_h1", "Frequency and gain of the largest H1 peak of each analysed "
                "window's model (windows the GFRF node skipped to keep up have no point).",
                {"freq_hz": freq, "gain_db": gain})


@styled
def change_over_time(hist: Mapping[str, Any]) -> Plot:
    fig, ax, t0, score = _panel(hist, "change_score", "change score S")
    thr = hist.get("change_threshold")
    data: dict[str, Any] = {"score": score, "threshold": None, "events": []}
    if thr is not None:
        line = ax.axhline(float(thr), color="tab:red", ls="--", label="threshold")
        data["threshold"] = float(np.asarray(line.get_ydata(), dtype=np.float64)[0])
    for i, e in enumerate(hist.get("events") or []):
        if e.get("t") is not None:
            ax.axvline(float(e["t"]) - t0, color="tab:purple", lw=1.5,
                       label="change event" if i == 0 else None)
            data["events"].append(float(e["t"]) - t0)
    ax.legend(loc="upper left")
    return Plot(fig, "run_change", "The change detector's combined score S per window; a "
                "change is reported when S stays at or above the threshold on two windows in a "
                "row (events: purple vertical lines).", data)


def _skipped(rows: Sequence[Mapping[str, Any]], stride: int) -> list[int]:
    seqs = sorted(int(r["seq"]) for r in rows if r.get("n_terms") is not None)
    return [s for a, b in itertools.pairwise(seqs) for s in range(a + stride, b, stride)]


@styled
def latency_over_time(hist: Mapping[str, Any]) -> Plot:
    fig, ax, t0, latency = _panel(hist, "fit_ms", "fit time (ms)")
    skipped: dict[str, list[int]] = {}
    for output, rows in hist["outputs"].items():
        skipped[output] = _skipped(rows, int((hist.get("stride") or {}).get(output, 1)))
        known = sorted((int(r["seq"]), float(r["t"])) for r in rows if r.get("t") is not None)
        if skipped[output] and known:
            seq, t = np.asarray(known).T
            ts = np.interp(skipped[output], seq, t) - t0  # between its neighbours in time
            ax.plot(ts, np.zeros(len(ts)), "x", color="tab:red", label=f"{output}: no model")
    ax.legend(loc="upper left")
    n = sum(len(v) for v in skipped.values())
    return Plot(fig, "run_latency", f"Fit time of each window's model; {n} window(s) with no "
                "model among those kept (skipped to keep up, or failed).",
                {"fit_ms": latency, "skipped": skipped})


MAX_EFFECT_PANELS = 8
COUNTS = ("effects_named", "unexplained", "force_nrmse_before", "force_nrmse_after")


def _drawn(line: Any) -> dict[str, Any]:
    return {"t": np.asarray(line.get_xdata()), "v": np.asarray(line.get_ydata())}


def _diagnosis_series(rows: Sequence[Mapping[str, Any]], key: str,
                      t0: float) -> tuple[Any, Any]:
    """(t, value) of every span; NaN where the span did not name the effect (a gap)."""
    rows = [r for r in rows if r.get("t") is not None]
    t = np.asarray([float(r["t"]) - t0 for r in rows])
    v = np.asarray([float((r.get("numbers") or {}).get(key, np.nan)) for r in rows])
    return t, v


def _effect_label(key: str) -> str:
    from ..topics import DIAGNOSIS_PARAMS

    effect, param = key.split("/", 1)
    unit = dict(DIAGNOSIS_PARAMS.get(effect, ())).get(param, "")
    return f"{effect}\n{param}" + (f" ({unit})" if unit and unit != "1" else "")


@styled
def diagnosis_over_time(hist: Mapping[str, Any]) -> Plot:
    rows = (hist.get("diagnosis") or {}).get("rows") or []
    t0 = _t0(hist)
    keys = list(dict.fromkeys(k for r in rows for k in r.get("numbers") or {}
                              if k not in COUNTS))[:MAX_EFFECT_PANELS]
    fig = new_figure(8.0, 2.4 + 1.8 * len(keys))
    axes = np.atleast_1d(fig.subplots(1 + len(keys), 1, sharex=True, squeeze=False)[:, 0])
    data: dict[str, Any] = {"nrmse": {}, "effects": {}}
    for key, label in (("force_nrmse_before", "plant"), ("force_nrmse_after", "with the effects")):
        t, v = _diagnosis_series(rows, key, t0)
        (line,) = axes[0].plot(t, v, ".-", markersize=3, label=label)
        data["nrmse"][key] = _drawn(line)
    axes[0].set_ylabel("held-out\nforce NRMSE")
    axes[0].set_title("each span diagnosed: the force NRMSE on its held-out last 30 %")
    axes[0].legend(loc="best")
    for ax, key in zip(axes[1:], keys, strict=True):
        t, v = _diagnosis_series(rows, key, t0)
        (line,) = ax.plot(t, v, "o-", markersize=3, color="tab:red")
        ax.set_ylabel(_effect_label(key))
        data["effects"][key] = _drawn(line)
    axes[-1].set_xlabel(XLABEL)
    named = ", ".join(keys) or "none"
    return Plot(fig, "run_diagnosis", "The live diagnosis span by span: the held-out force "
                "NRMSE of the plant and with the effects found, and the numbers of each effect "
                f"named in any span (a gap where a span did not name it). Effects: {named}.",
                data)


def figures(hist: Mapping[str, Any]) -> list[Plot]:
    """Every figure of the run history, in page order."""
    out = []
    if any(hist["outputs"].values()):
        out = [fit_over_time(hist), terms_over_time(hist), h1_over_time(hist),
               change_over_time(hist), latency_over_time(hist)]
    if (hist.get("diagnosis") or {}).get("rows"):
        out.append(diagnosis_over_time(hist))
    return out
