"""Figures in the paper's style (matplotlib, Agg, no pyplot state).

Every function builds one :class:`~.base.Plot`: the matplotlib ``Figure``, a file stem, a
caption, and ``data`` -- what was actually drawn, read back from the figure's artists (band
lines, ridge lines, curves), so a test can check that a figure is right, not just present.
The numerical core never imports this package; these functions take arrays and results.

=========================  ======================================  ==================
function                   shows                                   Liu et al. (2005)
=========================  ======================================  ==================
``io_series``              input and output of a window            Figs. 2, 7
``psd_pair``               Welch PSD of input and output           Figs. 3, 8
``predicted_vs_measured``  model predicted output (Eq. 12)         Figs. 4/9, 5/10
``correlation_tests``      the five tests of Eq. 13, 95% band      Figs. 6, 11
``h1_gain_phase``          H1 gain and phase, peaks marked         Figs. 12, 15
``h2_contour``             |H2| contour, ridges drawn              Fig. 13(b), 16
``h2_surface``             |H2| surface, ridges drawn              Fig. 13(a), 16
``h3_slice``               |H3| on f1 = f3, ridges drawn           Figs. 14, 17
=========================  ======================================  ==================
"""

from __future__ import annotations

from .base import Plot, save
from .correlation import correlation_tests
from .gfrf import RIDGE_LINES, h1_gain_phase, h2_contour, h2_surface, h3_slice, view_fmax
from .signals import io_series, predicted_vs_measured, psd_pair

__all__ = [
    "RIDGE_LINES", "Plot", "correlation_tests", "h1_gain_phase", "h2_contour", "h2_surface",
    "h3_slice", "io_series", "predicted_vs_measured", "psd_pair", "save", "view_fmax",
]
