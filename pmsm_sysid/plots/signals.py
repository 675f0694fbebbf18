"""Time-domain and spectral figures: input/output series (Figs. 2, 7 of Liu et al. 2005), Welch PSDs
(Figs. 3, 8) and the model predicted output against the measurements (Figs. 4/9, 5/10)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import Plot, hz_axis, new_figure, styled

FloatArray = NDArray[np.float64]
UNITS = {"thrust": "N", "speed": "m/s", "position": "m"}


def label(name: str) -> str:
    """Axis label with the SI unit of a recorded signal (``speed`` -> ``speed (m/s)``)."""
    unit = UNITS.get(name)
    return f"{name} ({unit})" if unit else name


def _line_data(line: Any) -> tuple[FloatArray, FloatArray]:
    return (np.asarray(line.get_xdata(), dtype=np.float64),
            np.asarray(line.get_ydata(), dtype=np.float64))


@styled
def io_series(k: ArrayLike, u: ArrayLike, y: ArrayLike, input_name: str = "thrust",
              output_name: str = "speed", window: str = "estimation",
              name: str = "io_series") -> Plot:
    """Input (a) and output (b) over sample index k (Figs. 2, 7 of Liu et al. 2005).

    ``data``: ``k``, ``u``, ``y`` as drawn.
    """
    fig = new_figure(8.0, 4.6)
    ax_u, ax_y = fig.subplots(2, 1, sharex=True)
    (lu,) = ax_u.plot(np.asarray(k), np.asarray(u), color="k")
    (ly,) = ax_y.plot(np.asarray(k), np.asarray(y), color="k")
    ax_u.set_ylabel(label(input_name))
    ax_u.set_title(f"(a) input: {input_name}")
    ax_y.set_ylabel(label(output_name))
    ax_y.set_title(f"(b) output: {output_name}")
    ax_y.set_xlabel("sample k")
    kk, uu = _line_data(lu)
    _, yy = _line_data(ly)
    caption = (f"Input ({input_name}) and output ({output_name}) of the {window} window, "
               f"samples {int(kk[0])}-{int(kk[-1])} (Figs. 2, 7 of Liu et al. 2005).")
    return Plot(fig, name, caption, {"k": kk, "u": uu, "y": yy})


@styled
def psd_pair(f_norm: ArrayLike, psd_u: ArrayLike, psd_y: ArrayLike, sample_rate_hz: float,
             input_name: str = "thrust", output_name: str = "speed",
             name: str = "psd") -> Plot:
    """Welch PSD of input (a) and output (b) over normalised frequency (Figs. 3, 8 of Liu et al.
    2005).

    ``data``: ``f_norm``, ``psd_u``, ``psd_y`` as drawn and each curve's peak frequency
    ``peak_u_norm`` / ``peak_y_norm`` (cycles/sample), read from the drawn lines.
    """
    fig = new_figure(8.0, 4.6)
    axes = fig.subplots(2, 1, sharex=True)
    out: dict[str, Any] = {}
    for ax, p, sig, tag, key in ((axes[0], psd_u, input_name, "(a) input", "u"),
                                 (axes[1], psd_y, output_name, "(b) output", "y")):
        (line,) = ax.semilogy(np.asarray(f_norm), np.maximum(np.asarray(p), 1e-300), color="k")
        ax.set_title(f"{tag}: {sig}")
        unit = UNITS.get(sig, "")
        ax.set_ylabel(f"PSD ({unit}²/Hz)" if unit else "PSD")
        ax.set_xlim(0.0, 0.5)
        hz_axis(ax, sample_rate_hz)
        f, v = _line_data(line)
        out["f_norm"], out[f"psd_{key}"] = f, v
        out[f"peak_{key}_norm"] = float(f[int(np.argmax(v))])
    axes[1].set_xlabel("normalised frequency (cycles/sample)")
    caption = (f"Power spectral density (Welch) of (a) the input {input_name} and (b) the "
               f"output {output_name}; peaks at {out['peak_u_norm']:.4f} and "
               f"{out['peak_y_norm']:.4f} cycles/sample = "
               f"{out['peak_u_norm'] * sample_rate_hz:.2f} and "
               f"{out['peak_y_norm'] * sample_rate_hz:.2f} Hz (Figs. 3, 8 of Liu et al. 2005).")
    return Plot(fig, name, caption, out)


def nmse(y: FloatArray, yhat: FloatArray) -> float:
    """sum (y - yhat)^2 / sum (y - mean y)^2; inf when the prediction is not finite
    throughout (a diverged free run is NaN from where it diverged)."""
    if not np.all(np.isfinite(yhat)):
        return float("inf")
    d = y - yhat
    return float(np.dot(d, d) / np.sum((y - y.mean()) ** 2))


@styled
def predicted_vs_measured(k: ArrayLike, y: ArrayLike, yhat: ArrayLike,
                          output_name: str = "speed", window: str = "estimation",
                          name: str = "predicted") -> Plot:
    """Measured output (solid) and the model predicted output (Eq. 12 of Liu et al. 2005; dotted on
    the estimation window, asterisks on validation as in Figs. 4 and 5), error below.

    ``data``: ``k``, ``measured``, ``predicted`` as drawn and their ``nmse``.
    """
    fig = new_figure(8.0, 4.6)
    ax, ax_e = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    kk = np.asarray(k, dtype=np.float64)
    (lm,) = ax.plot(kk, np.asarray(y), color="k", label="measured")
    style: dict[str, Any] = ({"linestyle": ":", "linewidth": 1.6} if window == "estimation"
                             else {"linestyle": "none", "marker": "*", "markersize": 3})
    (lp,) = ax.plot(kk, np.asarray(yhat), color="tab:red", label="model predicted output",
                    **style)
    _, ym = _line_data(lm)
    _, yp = _line_data(lp)
    score = nmse(ym, yp)
    bad = np.flatnonzero(~np.isfinite(yp))
    state = (f"diverged at sample {int(kk[bad[0]])}" if len(bad) else f"NMSE {score:.3g}")
    ax.set_ylabel(label(output_name))
    ax.legend(loc="upper right")
    ax.set_title(f"{window} window: model predicted output, {state}")
    ax_e.plot(kk, ym - yp, color="0.3")
    unit = UNITS.get(output_name)
    ax_e.set_ylabel(f"error ({unit})" if unit else "error")
    ax_e.set_xlabel("sample k")
    fig_no = "Figs. 4, 9" if window == "estimation" else "Figs. 5, 10"
    caption = (f"Model predicted output (Eq. 12: the model fed its own past outputs) against "
               f"the measured {output_name} on the {window} window, samples "
               f"{int(kk[0])}-{int(kk[-1])}; {state} (Liu et al. 2005, {fig_no}).")
    return Plot(fig, name, caption, {"k": kk, "measured": ym, "predicted": yp, "nmse": score})
