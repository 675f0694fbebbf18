"""Frequency-domain figures of an identified model (Section V of Liu et al. 2005): H1 gain and
phase (Figs. 12, 15), |H2| as contour and surface (Figs. 13, 16) and |H3| on the slice f1 = f3
(Figs. 14, 17), with the ridges of the gfrf JSON drawn as lines on the (f1, f2) plane.

A ridge ``{"kind", "sign", "freq_norm"}`` is the line a*x + b*y = sign*freq_norm with (a, b)
from :data:`RIDGE_LINES`: on H2's plane x = f1, y = f2; on H3's slice x = f1 = f3, y = f2
(so ``f1+f3`` is 2x = f0 and ``f1+f2+f3`` is 2x + y = f0). Frequencies are normalised
(cycles/sample) as in the paper; a top axis gives Hz.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import RegularGridInterpolator

from .base import Plot, hz_axis, new_figure, styled

FloatArray = NDArray[np.float64]
RIDGE_LINES: dict[str, tuple[int, int]] = {
    "f1": (1, 0), "f2": (0, 1), "f1+f2": (1, 1), "f1+f3": (2, 0), "f1+f2+f3": (2, 1),
}
COLOURS = {"f1": "tab:red", "f2": "tab:orange", "f1+f2": "magenta", "f1+f3": "tab:pink",
           "f1+f2+f3": "tab:cyan"}
NICE = (0.02, 0.025, 0.05, 0.075, 0.1, 0.125, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5)
FLOOR_DB = 80.0  # contours span at most this far below the maximum


def view_fmax(freqs: Sequence[float], factor: float = 1.6) -> float:
    """Half-width of a square view showing these frequencies with margin (seed: ±0.25)."""
    m = max((abs(float(f)) for f in freqs if np.isfinite(f)), default=0.25)
    return next((n for n in NICE if n >= factor * m), 0.5)


def _db(h: ArrayLike) -> FloatArray:
    a = np.abs(np.asarray(h))
    peak = float(np.max(a)) if a.size else 0.0
    floor = peak * 10 ** (-FLOOR_DB / 20) if peak > 0 else 1e-300
    return np.asarray(20 * np.log10(np.maximum(a, max(floor, 1e-300))), dtype=np.float64)


def segment(kind: str, c: float, fmax: float) -> tuple[FloatArray, FloatArray] | None:
    """End points of the line a*x + b*y = c inside [-fmax, fmax]^2 (None if outside)."""
    a, b = RIDGE_LINES[kind]
    lo, hi = -fmax, fmax
    if b == 0:
        x = c / a
        return (np.array([x, x]), np.array([lo, hi])) if lo <= x <= hi else None
    if a == 0:
        y = c / b
        return (np.array([lo, hi]), np.array([y, y])) if lo <= y <= hi else None
    x0, x1 = max(lo, (c - b * hi) / a), min(hi, (c - b * lo) / a)
    if x0 > x1:
        return None
    xs = np.array([x0, x1])
    return xs, (c - a * xs) / b


def _draw_ridges(ax: Any, ridges: Sequence[Mapping[str, Any]], fmax: float,
                 z: RegularGridInterpolator | None = None, z_floor: float = 0.0) -> list[Any]:
    drawn: list[dict[str, Any]] = []
    seen: set[str] = set()
    for r in ridges:
        kind = str(r["kind"])
        if kind not in RIDGE_LINES:
            continue
        c = float(r.get("sign", 1)) * float(r["freq_norm"])
        seg = segment(kind, c, fmax)
        if seg is None:
            continue
        dominant = bool(r.get("dominant", True))
        style = {"color": COLOURS[kind], "linewidth": 1.2 if dominant else 0.8,
                 "linestyle": (0, (5, 3)) if dominant else ":",
                 "label": f"ridge {kind}" if kind not in seen else None}
        seen.add(kind)
        if z is None:
            (line,) = ax.plot(seg[0], seg[1], **style)
            xs, ys = line.get_xdata(), line.get_ydata()
        else:
            xs = np.linspace(seg[0][0], seg[0][1], 60)
            ys = np.linspace(seg[1][0], seg[1][1], 60)
            zs = z(np.column_stack([ys, xs])) + 0.5  # just above the surface
            ax.plot(xs, ys, zs, zorder=3, **style)
            ax.plot(xs, ys, np.full_like(xs, z_floor), color=COLOURS[kind], linewidth=0.6,
                    zorder=0)
        drawn.append({"kind": kind, "sign": int(r.get("sign", 1)),
                      "freq_norm": float(r["freq_norm"]), "dominant": dominant,
                      "x": np.asarray(xs, dtype=np.float64),
                      "y": np.asarray(ys, dtype=np.float64)})
    return drawn


@styled
def h1_gain_phase(f_norm: ArrayLike, h1: ArrayLike, sample_rate_hz: float,
                  peaks: Sequence[Mapping[str, Any]] = (), title: str = "",
                  name: str = "h1", phase: bool = True,
                  excited: Sequence[tuple[float, float]] | None = None,
                  gain_unit: str = "") -> Plot:
    """Gain (dB) and phase (deg) of H1 over [0, 0.5] cycles/sample, peaks marked
    (``phase=False``: gain only, for magnitudes without phase). ``excited``: the intervals
    (cycles/sample) where the estimation input has power, shaded. ``gain_unit``: the unit of
    |H1| (output unit per input unit), for the axis label "gain (dB re 1 unit)".

    ``data``: ``f_norm``, ``gain_db``, ``phase_deg`` (empty without phase) and ``peaks``
    [(freq_norm, gain_db)] as drawn.
    """
    f = np.asarray(f_norm, dtype=np.float64)
    h = np.asarray(h1, dtype=np.complex128)
    fig = new_figure(8.0, 4.8 if phase else 3.2)
    if phase:
        ax_g, ax_p = fig.subplots(2, 1, sharex=True)
    else:
        ax_g, ax_p = fig.subplots(), None
    (lg,) = ax_g.plot(f, 20 * np.log10(np.maximum(np.abs(h), 1e-300)), color="k")
    for i, (lo, hi) in enumerate(excited or ()):
        for ax in (ax_g, ax_p):
            if ax is not None:
                ax.axvspan(lo, hi, color="tab:green", alpha=0.25, lw=0,
                           label="input has power" if ax is ax_g and i == 0 else None)
    phase_deg = np.zeros(0)
    if ax_p is not None:
        (lp,) = ax_p.plot(f, np.degrees(np.angle(h)), color="k")
        phase_deg = np.asarray(lp.get_ydata(), dtype=np.float64)
        ax_p.set_ylabel("phase (deg)")
        ax_p.set_ylim(-200, 200)
        ax_p.set_xlabel("normalised frequency (cycles/sample)")
    else:
        ax_g.set_xlabel("normalised frequency (cycles/sample)")
    pk = [(float(p["freq_norm"]), float(p["gain_db"])) for p in peaks]
    marks = _mark_peaks(ax_g, pk)
    if pk or excited:
        ax_g.legend(loc="upper right")
    ax_g.set_ylabel(f"gain (dB re 1 {gain_unit})" if gain_unit else "gain (dB)")
    ax_g.set_title(title or "first-order GFRF H1(f)")
    ax_g.set_xlim(0.0, 0.5)
    hz_axis(ax_g, sample_rate_hz)
    return Plot(fig, name, _h1_caption(pk, sample_rate_hz, phase, excited), {
        "f_norm": np.asarray(lg.get_xdata(), dtype=np.float64),
        "gain_db": np.asarray(lg.get_ydata(), dtype=np.float64),
        "phase_deg": phase_deg, "peaks": marks})


def _mark_peaks(ax: Any, pk: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Triangles at the peaks; returns the marked points read back from the artist."""
    if not pk:
        return []
    (lm,) = ax.plot([p[0] for p in pk], [p[1] for p in pk], "v", color="tab:red",
                    markersize=6, label="H1 peaks (gfrf)")
    return list(zip(np.asarray(lm.get_xdata()).tolist(), np.asarray(lm.get_ydata()).tolist(),
                    strict=True))


def _h1_caption(pk: list[tuple[float, float]], fs: float, phase: bool,
                excited: Sequence[tuple[float, float]] | None) -> str:
    top = max(pk, key=lambda p: p[1]) if pk else None
    where = (f"; largest peak {top[1]:.1f} dB at {top[0]:.4f} cycles/sample = "
             f"{top[0] * fs:.2f} Hz" if top else "")
    spans = ", ".join(f"{lo:.4f}-{hi:.4f} cycles/sample ({lo * fs:.1f}-{hi * fs:.1f} Hz)"
                      for lo, hi in excited or ())
    band = (f"; shaded: where the estimation input has power, {spans} "
            "(elsewhere H1 is extrapolated)" if spans else "")
    return (f"First-order GFRF H1: gain{' and phase' if phase else ''}{where}{band} "
            "(Figs. 12, 15 of Liu et al. 2005).")


def _ridge_caption(drawn: Sequence[Mapping[str, Any]], fs: float) -> str:
    pos = sorted({(d["kind"], round(d["freq_norm"], 4)) for d in drawn if d["dominant"]},
                 key=lambda t: (t[1], t[0]))
    if not pos:
        return "no ridge in view"
    return "ridges " + ", ".join(f"{k} = ±{f:.4f} ({f * fs:.2f} Hz)" for k, f in pos[:8])


@styled
def h2_contour(f: ArrayLike, h2: ArrayLike, sample_rate_hz: float,
               ridges: Sequence[Mapping[str, Any]] = (), title: str = "",
               name: str = "h2_contour", order: int = 2) -> Plot:
    """Filled contour of 20 log10 |H(f1, f2)| (``h2[i, j]`` at f1 = f[i], f2 = f[j]) with
    the ridge lines drawn. Also used for the H3 slice (``order=3``).

    ``data``: ``f``, ``db`` (the array contoured, rows f2 and columns f1 as drawn), ``fmax``
    and ``ridges``: per drawn ridge its kind, sign, freq_norm and line end points x, y.
    """
    ff = np.asarray(f, dtype=np.float64)
    db = _db(h2).T  # rows f2 (y), columns f1 (x)
    fmax = float(ff[-1])
    fig = new_figure(7.0, 6.0)
    ax = fig.subplots()
    cs = ax.contourf(ff, ff, db, levels=24, cmap="viridis")
    fig.colorbar(cs, ax=ax, label=f"|H{order}| (dB)")
    drawn = _draw_ridges(ax, ridges, fmax)
    ax.set_xlim(-fmax, fmax)
    ax.set_ylim(-fmax, fmax)
    ax.set_aspect("equal")
    sub = "f1 = f3" if order == 3 else ""
    ax.set_xlabel("normalised frequency f1" + (" = f3" if order == 3 else "") +
                  " (cycles/sample)")
    ax.set_ylabel("normalised frequency f2 (cycles/sample)")
    ax.set_title(title or (f"|H3(f1, f2, f1)| on the slice {sub}" if order == 3
                           else "|H2(f1, f2)|, contour"))
    if drawn:
        ax.legend(loc="upper right", framealpha=0.6)
    figs = "Figs. 14, 17" if order == 3 else "Figs. 13(b), 16"
    what = "H3 on the slice f1 = f3" if order == 3 else "H2"
    caption = (f"Contour of |{what}| in dB over ±{fmax:g} cycles/sample "
               f"(±{fmax * sample_rate_hz:g} Hz); {_ridge_caption(drawn, sample_rate_hz)} "
               f"(Liu et al. 2005, {figs}).")
    return Plot(fig, name, caption, {"f": ff, "db": db, "fmax": fmax, "ridges": drawn})


@styled
def h2_surface(f: ArrayLike, h2: ArrayLike, sample_rate_hz: float,
               ridges: Sequence[Mapping[str, Any]] = (), title: str = "",
               name: str = "h2_surface", max_points: int = 97) -> Plot:
    """Surface of 20 log10 |H2(f1, f2)| with the ridges drawn on it and on the floor.

    ``data``: ``f`` and ``db`` of the (sub-sampled) surface, ``ridges`` as drawn (x, y).
    """
    ff = np.asarray(f, dtype=np.float64)
    db_full = _db(h2).T
    step = max(1, int(np.ceil(len(ff) / max_points)))
    fs_, db = ff[::step], db_full[::step, ::step]
    fig = new_figure(7.0, 6.0)
    ax = fig.add_subplot(projection="3d")
    ax.computed_zorder = False  # ridge lines stay visible over the surface
    x, y = np.meshgrid(fs_, fs_)
    ax.plot_surface(x, y, db, cmap="viridis", linewidth=0, antialiased=False,
                    rcount=len(fs_), ccount=len(fs_), zorder=1)
    z_floor = float(np.min(db))
    interp = RegularGridInterpolator((ff, ff), db_full, bounds_error=False, fill_value=None)
    drawn = _draw_ridges(ax, ridges, float(ff[-1]), interp, z_floor)
    ax.set_xlabel("f1 (cycles/sample)")
    ax.set_ylabel("f2 (cycles/sample)")
    ax.set_zlabel("|H2| (dB)")
    ax.set_title(title or "|H2(f1, f2)|, surface")
    ax.view_init(elev=35, azim=-60)
    caption = (f"Surface of |H2| in dB over ±{ff[-1]:g} cycles/sample with the detected "
               f"ridges drawn on it; {_ridge_caption(drawn, sample_rate_hz)} "
               "(Figs. 13(a), 16 of Liu et al. 2005).")
    return Plot(fig, name, caption, {"f": fs_, "db": db, "ridges": drawn})


def h3_slice(f: ArrayLike, h3: ArrayLike, sample_rate_hz: float,
             ridges: Sequence[Mapping[str, Any]] = (), title: str = "",
             name: str = "h3_slice") -> Plot:
    """Contour of |H3(f1, f2, f1)| (``h3[i, j]`` at f1 = f3 = f[i], f2 = f[j]) with the H3
    ridges of the gfrf JSON; ``data`` as :func:`h2_contour`."""
    return h2_contour(f, h3, sample_rate_hz, ridges, title=title, name=name, order=3)
