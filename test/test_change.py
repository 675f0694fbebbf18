"""Change detection statistics (core/change.py) on synthetic feature streams."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmsm_sysid.core.change import (
    ChangeConfig,
    ChangeDetector,
    FeatureSpec,
    RobustBaseline,
    jaccard_distance,
    nrmse,
)
from pmsm_sysid.core.errors import DataError

FEATURES = (
    FeatureSpec("err", one_sided=True, floor=1e-3, rel_floor=0.05),
    FeatureSpec("gain_db", floor=0.1),
    FeatureSpec("jac", one_sided=True, floor=0.05),
)


def _stream(n: int, seed: int) -> list[dict[str, float]]:
    """Stationary features with realistic shapes: a skewed positive error, a Gaussian gain,
    a bounded and lumpy term-set distance."""
    rng = np.random.default_rng(seed)
    err = 0.08 * np.exp(0.25 * rng.standard_normal(n))
    gain = 46.0 + 0.3 * rng.standard_normal(n)
    jac = np.clip(rng.beta(4, 3, n), 0, 1)
    return [{"err": e, "gain_db": g, "jac": j} for e, g, j in zip(err, gain, jac, strict=True)]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_false_alarm_over_a_long_stationary_run(seed: int) -> None:
    det = ChangeDetector(FEATURES)
    decisions = [det.update(i, f) for i, f in enumerate(_stream(5000, seed))]
    assert [d.seq for d in decisions if d.changed] == []
    assert decisions[0].state == "learning" and decisions[-1].state == "steady"
    assert max(d.score for d in decisions) < ChangeConfig().z_fire


@pytest.mark.parametrize("feature,delta", [("err", 0.5), ("err", 0.2), ("gain_db", -3.0)])
def test_a_step_is_reported_within_three_windows(feature: str, delta: float) -> None:
    stream = _stream(400, 7)
    for f in stream[200:]:
        f[feature] += delta
    det = ChangeDetector(FEATURES)
    changes = [i for i, f in enumerate(stream) if det.update(i, f).changed]
    assert changes and 200 <= changes[0] <= 202
    assert feature in det.events[0].reasons
    assert changes == [changes[0]]  # the new regime is relearnt, no repeated alarms


def test_error_increase_is_one_sided() -> None:
    stream = _stream(300, 3)
    for f in stream[150:]:
        f["err"] *= 0.3  # the model got better: not a plant change by this feature
    det = ChangeDetector(FEATURES[:1])
    assert not any(det.update(i, f).changed for i, f in enumerate(stream))


def test_non_finite_error_needs_two_windows_and_missing_values_are_skipped() -> None:
    det = ChangeDetector(FEATURES)
    for i, f in enumerate(_stream(50, 4)):
        det.update(i, f)
    d = det.update(50, {"gain_db": math.nan})
    assert d.state == "steady" and math.isnan(d.z["gain_db"])
    d = det.update(51, {"err": math.inf})  # e.g. one diverged free run: not yet a change
    assert d.state == "steady" and d.z["err"] == ChangeConfig().z_confirm
    d = det.update(52, {"err": math.inf})
    assert d.changed and d.reasons == ("err",)


def test_a_single_moderate_outlier_needs_confirmation() -> None:
    stream = _stream(100, 5)
    det = ChangeDetector(FEATURES)
    for i, f in enumerate(stream[:60]):
        det.update(i, f)
    med, scale = det._base["gain_db"].centre_scale()
    one = dict(stream[60], gain_db=med + 8 * scale)  # between z_confirm and z_fire
    assert det.update(60, one).state == "steady"
    two = dict(stream[61], gain_db=med + 8 * scale)
    assert det.update(61, two).changed


def test_robust_baseline_matches_numpy_median_and_mad() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(30)
    b = RobustBaseline(size=20, floor=0.0)
    for v in x:
        b.add(float(v))
    b.add(math.nan)
    tail = x[-20:]
    med = np.median(tail)
    assert b.centre_scale() == pytest.approx((med, 1.4826 * np.median(np.abs(tail - med))))
    assert len(b) == 20


def test_scale_floors_apply() -> None:
    b = RobustBaseline(10, floor=0.2, rel_floor=0.1)
    for _ in range(10):
        b.add(5.0)
    assert b.centre_scale() == (5.0, 0.5)
    assert b.z(6.0, True) == pytest.approx(2.0) and b.z(4.0, False) == pytest.approx(2.0)
    assert b.z(4.0, True) == pytest.approx(-2.0)


def test_jaccard_and_nrmse_closed_forms() -> None:
    assert jaccard_distance(["a", "b", "c"], ["b", "c", "d"]) == pytest.approx(0.5)
    assert jaccard_distance([], []) == 0.0 and jaccard_distance(["a"], ["b"]) == 1.0
    y = np.sin(np.linspace(0, 10, 500))
    assert nrmse(y, y) == 0.0
    assert nrmse(y, y + 0.1) == pytest.approx(0.1 / np.std(y))
    assert nrmse(y, np.full_like(y, y.mean())) == pytest.approx(1.0)
    assert nrmse(y, np.full_like(y, np.inf)) == math.inf
    with pytest.raises(DataError):
        nrmse(y, y[:-1])


def test_bad_config_is_rejected() -> None:
    with pytest.raises(DataError):
        ChangeConfig(warmup=2)
    with pytest.raises(DataError):
        ChangeConfig(z_fire=3, z_confirm=5)
    with pytest.raises(DataError):
        ChangeDetector([])


def test_after_a_change_the_window_spanning_it_is_not_learnt() -> None:
    """holdoff windows (still holding pre-change data) are skipped, then warmup relearns."""
    stream = _stream(120, 8)
    for f in stream[60:]:
        f["gain_db"] -= 5.0
    cfg = ChangeConfig(holdoff=3, warmup=8)
    det = ChangeDetector(FEATURES, cfg)
    states = [det.update(i, f).state for i, f in enumerate(stream)]
    k = states.index("change")
    assert 60 <= k <= 61
    assert states[k + 1:k + 4] == ["settling"] * 3
    assert states[k + 4:k + 12] == ["learning"] * 8
    assert set(states[k + 12:]) == {"steady"}
