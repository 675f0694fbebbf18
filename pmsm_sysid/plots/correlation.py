"""The five model validity tests of Eq. 13 of Liu et al. (2005) with their 95% bands (Figs. 6,
11)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.validation.correlation import CorrelationTest, CorrelationTests
from .base import Plot, new_figure, styled

TITLES = {
    "ee": "φ_εε(τ)",
    "ue": "φ_uε(τ)",
    "u2e": "φ_u²'ε(τ)",
    "u2e2": "φ_u²'ε²'(τ)",
    "e_eu": "φ_ε(εu)(τ)",
}


def _panel(ax: Any, test: CorrelationTest) -> dict[str, Any]:
    lags = np.asarray(test.lags, dtype=np.float64)
    vals = np.asarray(test.values, dtype=np.float64)
    ax.vlines(lags, 0.0, vals, color="k", linewidth=1.0)
    (pts,) = ax.plot(lags, vals, "k.", markersize=3)
    lo, hi = float(lags.min()) - 0.5, float(lags.max()) + 0.5
    (up,) = ax.plot([lo, hi], [test.band, test.band], "--", color="tab:blue", gid="band")
    (dn,) = ax.plot([lo, hi], [-test.band, -test.band], "--", color="tab:blue", gid="band")
    top = max(1.25 * float(np.max(np.abs(vals), initial=0.0)), 2.0 * test.band)
    ax.set_ylim(-top, top)
    ax.set_xlim(lo, hi)
    verdict = "pass" if test.passed else "FAIL"
    ax.set_title(f"{TITLES.get(test.name, test.name)}  [{verdict}, "
                 f"{test.n_outside}/{len(test.lags)} outside]",
                 color="k" if test.passed else "tab:red")
    ax.set_xlabel("lag τ (samples)")
    return {"lags": np.asarray(pts.get_xdata(), dtype=np.float64),
            "values": np.asarray(pts.get_ydata(), dtype=np.float64),
            "band_upper": float(np.asarray(up.get_ydata())[0]),
            "band_lower": float(np.asarray(dn.get_ydata())[0]),
            "passed": test.passed}


@styled
def correlation_tests(tests: CorrelationTests, n_samples: int, window: str = "estimation",
                      name: str = "correlation_tests") -> Plot:
    """Five panels: the normalised correlations per lag and the 95% band ±1.96/√N.

    ``n_samples`` is N, the number of residuals the tests used; the drawn band is checked
    against it. ``data``: per test name, ``lags``, ``values``, ``band_upper``,
    ``band_lower`` (read back from the drawn lines) and ``passed``; plus ``n_samples``.
    """
    fig = new_figure(8.0, 7.0)
    axes = fig.subplots(3, 2)
    flat = list(axes.ravel())
    data: dict[str, Any] = {"n_samples": int(n_samples)}
    for ax, test in zip(flat, tests.tests(), strict=False):
        data[test.name] = _panel(ax, test)
    note = flat[-1]
    note.axis("off")
    band = 1.96 / np.sqrt(n_samples)
    verdict = "all five pass" if tests.all_pass else "not all pass"
    note.text(0.02, 0.9, f"N = {n_samples} residuals ({window} window)\n"
              f"95% band ±1.96/√N = ±{band:.4f}\n{verdict}",
              va="top", ha="left", transform=note.transAxes, fontsize=9)
    caption = (f"Model validity tests (Eq. 13 of Liu et al. 2005) on the one-step-ahead "
               f"residuals of the "
               f"{window} window, N = {n_samples}; dashed: the 95% band ±1.96/√N = "
               f"±{band:.4f}; {verdict} (Figs. 6, 11 of Liu et al. 2005).")
    return Plot(fig, name, caption, data)
