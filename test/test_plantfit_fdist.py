"""The fit's F-distribution tail (:func:`pmsm_sysid.core.plantfit.stats.f_logsf`) gives
what ``scipy.stats.f.logsf`` gives, bit for bit, across and at the edges of its range; the
held-out test's normal tail is ``scipy.stats.norm.sf``; and the whitening filter gives what
``scipy.signal.lfilter`` gives, bit for bit and with its strides."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, special, stats

from pmsm_sysid.core.plantfit.stats import f_logsf, whiten

#: Degrees of freedom of the tests the fit makes (small numerators, a few hundred to
#: thousands of samples), and fractional ones
DFN = (1, 2, 3, 4, 8, 16, 40, 0.5, 2.5)
DFD = (1, 5, 30, 300, 681, 3000, 2.5)


def _same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def test_f_logsf_is_scipys() -> None:
    rng = np.random.default_rng(3)
    xs = [0.0, -1.0, math.inf, math.nan, 1e-300, 1e300,
          *rng.lognormal(0.0, 3.0, 300).tolist()]
    for dfn in DFN:
        for dfd in DFD:
            median = float(stats.f.median(dfn, dfd))  # both branches, and the switch
            for x in [*xs, median, np.nextafter(median, math.inf)]:
                want = float(stats.f.logsf(x, dfn, dfd))
                assert _same(f_logsf(x, dfn, dfd), want), (x, dfn, dfd)


def test_f_logsf_refuses_what_scipy_refuses() -> None:
    for dfn, dfd in ((0, 5), (2, 0), (-1, 5)):
        assert math.isnan(f_logsf(2.0, dfn, dfd))
        assert math.isnan(float(stats.f.logsf(2.0, dfn, dfd)))


def test_normal_tail_is_scipys() -> None:
    for z in (-40.0, -3.0, -1e-3, 0.0, 0.5, 2.0, 8.0, 40.0, math.inf, -math.inf):
        assert float(special.ndtr(-z)) == float(stats.norm.sf(z))


@pytest.mark.parametrize("n", [5, 21, 683, 3499])
def test_whiten_is_lfilter(n: int) -> None:
    rng = np.random.default_rng(n)
    for shape in ((n,), (n, 1), (n, 2), (n, 33)):
        for order in (0, 1, 3, 20):
            poly = np.concatenate([[1.0], 0.3 * rng.standard_normal(order)])
            a = rng.standard_normal(shape)
            got, want = whiten(poly, a), signal.lfilter(poly, [1.0], a, axis=0)[order:]
            assert got.shape == want.shape and got.strides == want.strides
            assert got.tobytes() == want.tobytes()
