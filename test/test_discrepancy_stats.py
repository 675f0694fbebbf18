"""Inference under coloured noise: AR whitening, nested F-tests, held-out comparison, ERR."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.signal import lfilter

from pmsm_sysid.core.plantfit.stats import (
    ar_whitener,
    held_out_test,
    nested_f_test,
    nrmse,
)


def test_ar_whitener_recovers_an_ar2_process() -> None:
    rng = np.random.default_rng(0)
    e = lfilter([1.0], [1.0, -1.2, 0.5], rng.normal(size=20000))
    poly = ar_whitener(e)
    assert len(poly) - 1 == 2  # BIC picks the true order
    assert poly[1:] == pytest.approx([-1.2, 0.5], abs=0.03)


def test_f_test_without_whitening_is_the_classical_one() -> None:
    """poly = [1]: the statistic equals the textbook nested F from two OLS fits."""
    rng = np.random.default_rng(1)
    n = 300
    base = np.column_stack([np.ones(n), rng.normal(size=n)])
    extra = rng.normal(size=(n, 2))
    y = base @ [1.0, 2.0] + 0.3 * extra[:, 0] + rng.normal(size=n)
    t = nested_f_test(y, base, extra, poly=np.ones(1))
    r0 = y - base @ np.linalg.lstsq(base, y, rcond=None)[0]
    full = np.hstack([base, extra])
    r1 = y - full @ np.linalg.lstsq(full, y, rcond=None)[0]
    f = ((r0 @ r0 - r1 @ r1) / 2) / (r1 @ r1 / (n - 4))
    assert t.f_stat == pytest.approx(f, rel=1e-9)
    assert t.log10_p == pytest.approx(math.log10(stats.f.sf(f, 2, n - 4)), rel=1e-6)


def test_f_test_size_under_coloured_noise() -> None:
    """Under H0 with strongly coloured noise the prewhitened test keeps its level; the
    unwhitened one would reject far too often."""
    rng = np.random.default_rng(2)
    n, trials = 400, 300
    x = np.sin(np.linspace(0, 12 * np.pi, n))[:, None]  # a slow regressor, like a friction term
    p_white, p_naive = [], []
    for _ in range(trials):
        y = lfilter([1.0], [1.0, -0.9], rng.normal(size=n))
        p_white.append(10 ** nested_f_test(y, np.zeros((n, 0)), x).log10_p)
        p_naive.append(10 ** nested_f_test(y, np.zeros((n, 0)), x, poly=np.ones(1)).log10_p)
    assert np.mean(np.array(p_white) < 0.05) < 0.10
    assert np.mean(np.array(p_naive) < 0.05) > 0.3


def test_f_test_power_and_bonferroni() -> None:
    rng = np.random.default_rng(3)
    n = 400
    x = rng.normal(size=(n, 1))
    y = 0.5 * x[:, 0] + rng.normal(size=n)
    t = nested_f_test(y, np.zeros((n, 0)), x)
    assert t.log10_p < -10
    assert t.corrected_log10_p(100) == pytest.approx(t.log10_p + 2.0)
    assert t.corrected_log10_p(1e300) == 0.0  # capped at p = 1


def test_held_out_confirms_a_real_reduction_only() -> None:
    rng = np.random.default_rng(4)
    n = 600
    effect = 1.5 * np.sin(np.arange(n) / 7.0)
    noise = lfilter([1.0], [1.0, -0.6], rng.normal(size=n))
    real = held_out_test(noise + effect, noise)  # the model removes an effect that is there
    assert real.confirmed and real.reduction > 0.1
    # the model subtracts a contribution the data do not hold: worse, never confirmed
    wrong = held_out_test(noise, noise - 0.3 * np.sin(np.arange(n) / 3.0))
    assert not wrong.confirmed and wrong.reduction < 0


def test_nrmse() -> None:
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert nrmse(y, np.zeros(4)) == 0.0
    assert nrmse(y, y - y.mean()) == pytest.approx(1.0)
