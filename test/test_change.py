"""Change detection statistics (core/change.py) on synthetic feature streams."""

from __future__ import annotations

import math
from itertools import pairwise
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.online.change import (
    ChangeConfig,
    ChangeDetector,
    FeatureSpec,
    RobustBaseline,
    combined_score,
    jaccard_distance,
)

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
    scores = [d.score for d in decisions]
    assert max(min(a, b) for a, b in pairwise(scores)) < ChangeConfig().s_confirm


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
    assert d.state == "steady" and math.isnan(d.z["gain_db"]) and d.score == 0
    d = det.update(51, {"err": math.inf})  # e.g. one diverged free run: not yet a change
    assert d.state == "steady" and d.score == ChangeConfig().z_cap
    d = det.update(52, {"err": math.inf})
    assert d.changed and d.reasons == ("err",)


def test_a_single_moderate_outlier_needs_confirmation() -> None:
    stream = _stream(100, 5)
    det = ChangeDetector(FEATURES)
    for i, f in enumerate(stream[:60]):
        det.update(i, f)
    med, scale = det._base["gain_db"].centre_scale()
    one = dict(stream[60], gain_db=med + 10 * scale)  # score over s_confirm, one window
    d = det.update(60, one)
    assert d.state == "steady" and d.score >= ChangeConfig().s_confirm
    assert det.update(61, stream[61]).state == "steady"  # not persistent: forgotten
    for k in (62, 63):
        d = det.update(k, dict(stream[k], gain_db=med + 10 * scale))
    assert d.changed and d.reasons[0] == "gain_db"


def test_several_moderate_shifts_add_up() -> None:
    """No feature alone is far out, but three at once, twice, are a change."""
    stream = _stream(100, 6)
    det = ChangeDetector(FEATURES)
    for i, f in enumerate(stream[:60]):
        det.update(i, f)
    shifted = {}
    for k in FEATURES:
        med, scale = det._base[k.name].centre_scale()
        shifted[k.name] = med + 5.5 * scale
    assert math.sqrt(3 * 5.5**2) >= ChangeConfig().s_confirm
    assert det.update(60, shifted).state == "steady"
    d = det.update(61, shifted)
    assert d.changed and set(d.reasons) == {"err", "gain_db", "jac"}


def test_combined_score_closed_form() -> None:
    z = {"a": 3.0, "b": -4.0, "c": 30.0, "d": math.nan, "e": math.inf}
    assert combined_score(z, cap=20.0) == pytest.approx(math.sqrt(9 + 0 + 400 + 400))


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


def test_a_baseline_scores_nothing_before_it_holds_three_values() -> None:
    """A feature observed only under some inputs has no reference at first: no z-score."""
    b = RobustBaseline(10)
    assert math.isnan(b.z(1.0, False)) and math.isnan(b.z(1.0, True))
    assert b.z(math.inf, True) == math.inf  # a diverged free run still counts
    for v in (1.0, 2.0):
        b.add(v)
    assert math.isnan(b.z(5.0, True))
    b.add(3.0)
    assert b.z(5.0, True) > 0


def test_harmonic_content_is_observed_only_when_the_input_has_none_there() -> None:
    """Under a tone the output's harmonics are the plant's; under APRBS or PRBS they are the
    input's own (each window's differ), so the feature is left out."""
    from pmsm_sysid.core.online.features import (
        INPUT_HARMONICS_MAX_DB,
        harmonics_db,
        plant_harmonics_db,
    )
    from pmsm_sysid.core.physics.excitation import make_excitation

    k = np.arange(1000)
    tone = 10.0 * np.sin(2 * np.pi * 16.5 / 500 * k)
    distorted = 0.03 * tone + 1e-3 * np.sin(2 * np.pi * 33.0 / 500 * k)
    got = plant_harmonics_db(distorted, tone)
    assert got == pytest.approx(harmonics_db(distorted, 16.5 / 500))
    assert got == pytest.approx(20 * math.log10(1e-3 / 0.3), abs=0.1)
    for kind in ("aprbs", "prbs", "multisine", "broadband"):
        u = make_excitation(kind, 20000, 500.0, seed=0)
        for stop in range(1000, 20001, 1000):
            w = u[stop - 1000:stop]
            assert math.isnan(plant_harmonics_db(w, w)), (kind, stop)
    assert INPUT_HARMONICS_MAX_DB <= -40.0


def test_after_a_change_the_old_spread_bounds_the_scale_until_the_baseline_is_full() -> None:
    """A few windows of warm-up show only part of the excitation's window-to-window spread:
    the spread from before the change stays a floor of the scale until the baseline is full."""
    b = RobustBaseline(10)
    for v in (1.0, 3.0, 5.0, 7.0, 9.0, 2.0, 4.0, 6.0, 8.0, 10.0):
        b.add(v)
    old = b.centre_scale()[1]
    b.clear(keep_spread=True)
    for _ in range(9):
        b.add(20.0)
        assert b.centre_scale() == (20.0, old)
    b.add(20.0)  # full again: its own scale (here the 1e-300 guard) rules
    assert b.centre_scale()[1] < 1e-200
    b.clear()  # a restart forgets the spread too
    for _ in range(3):
        b.add(20.0)
    assert b.centre_scale()[1] < 1e-200


def test_the_detector_keeps_the_spread_across_a_change() -> None:
    stream = _stream(160, 9)
    for f in stream[100:]:
        f["gain_db"] -= 5.0
    det = ChangeDetector(FEATURES, ChangeConfig(baseline=24, warmup=8, holdoff=3))
    scale = 0.0
    for i, f in enumerate(stream):
        if det.update(i, f).changed:
            break
        scale = det._base["gain_db"].centre_scale()[1]
    k = i
    for i in range(k + 1, k + 1 + 3 + 8):  # settling, then learning
        det.update(i, stream[i])
    assert det._base["gain_db"].centre_scale()[1] >= scale
    assert det._base["gain_db"].centre_scale()[0] == pytest.approx(
        np.median([f["gain_db"] for f in stream[k + 4:k + 12]]))


def test_the_fit_error_has_one_scale_for_the_run() -> None:
    """The own-fit feature is the free-run RMS error over the first window's output spread:
    a window whose output swings less (another stretch of an APRBS) with the same error,
    the plant's noise, scores the same."""
    from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config
    from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS as DEFAULTS

    track = WindowTracker(tracker_config(DEFAULTS))._tracks["speed"]
    wide, narrow = np.array([-2.0, 2.0] * 50), np.array([-1.0, 1.0] * 50)
    fit = WindowTracker._fit_error
    ok = {"free_run_diverged": False}
    assert fit(track, wide, {**ok, "nrmse": 0.01}) == pytest.approx(0.01)
    assert fit(track, narrow, {**ok, "nrmse": 0.02}) == pytest.approx(0.01)  # same RMS error
    assert fit(track, narrow, {**ok, "nrmse": None}) == math.inf
    assert fit(track, narrow, {"free_run_diverged": True, "nrmse": 0.02}) == math.inf


def test_the_out_of_sample_error_is_the_best_of_the_last_two_models() -> None:
    """One odd fit (a spurious cross term) scores in its own window, not again in the next
    one's out-of-sample error; a model of another plant fails either way."""
    from narx_systems import LINEAR, simulate, white_input

    from pmsm_sysid.core.online.features import best_newest_error, newest_error
    from pmsm_sysid.core.terms.model import NarxModel, Term

    def model(coeffs: dict[str, float]) -> NarxModel:
        return NarxModel(terms=tuple(Term.parse(n) for n in coeffs),
                         estimates=np.array(list(coeffs.values())))

    u = white_input(1200)
    y = simulate(LINEAR, u, noise_std=0.01)
    good, odd = model(LINEAR), model({**LINEAR, "y(k-1)u(k-2)": 0.3})
    other = model({**LINEAR, "u(k-1)": 1.5})  # the plant's gain changed
    assert newest_error(odd, y, u, 250) > 10 * newest_error(good, y, u, 250)
    assert best_newest_error([odd, good], y, u, 250) == newest_error(good, y, u, 250)
    assert best_newest_error([other, other], y, u, 250) > 10 * newest_error(good, y, u, 250)


def test_jaccard_closed_forms() -> None:
    assert jaccard_distance(["a", "b", "c"], ["b", "c", "d"]) == pytest.approx(0.5)
    assert jaccard_distance([], []) == 0.0 and jaccard_distance(["a"], ["b"]) == 1.0


def test_bad_config_is_rejected() -> None:
    with pytest.raises(DataError):
        ChangeConfig(warmup=2)
    with pytest.raises(DataError):
        ChangeConfig(s_confirm=0)
    with pytest.raises(DataError):
        ChangeConfig(holdoff=-1)
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


# --- calibration on the simulated motor: the tracker's features on real fits ----------------

def _simulate(plant: Any, n: int, seed: int, change_at: int | None = None,
              after: Any = None, amplitude_n: float = 10.0) -> np.ndarray:
    from pmsm_sysid.core.physics.excitation import make_excitation
    from pmsm_sysid.core.physics.motor import MotorSimulator

    u = make_excitation("paper-speed", n, plant.sample_rate_hz, seed=seed,
                        amplitude_n=amplitude_n)
    sim = MotorSimulator(plant, seed=seed)
    out = np.empty((n, 3))
    for k in range(n):
        if k == change_at:
            sim.set_plant(after)
        out[k, 1:] = sim.measure()
        out[k, 0] = sim.measured_thrust(u[k])  # what the thrust sensor records
        sim.advance(u[k])
    return out


def _changes(data: np.ndarray) -> list[int]:
    """Stops of the windows where the speed tracker reports a change (paper defaults)."""
    from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config
    from pmsm_sysid.core.online.windows import Window
    from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS as DEFAULTS

    tracker = WindowTracker(tracker_config({**DEFAULTS, "outputs": ["speed"]}))
    h, out = tracker.history, []
    for stop in range(1250, len(data) + 1, 250):
        a = stop - 1000
        w = Window(stop // 250, a, stop, h, np.arange(a - h, stop, dtype=np.int64) * 2_000_000,
                   data[a - h:stop])
        r = tracker.process(w)
        assert not r.errors, r.errors
        out += [stop for c in r.changes]
    return out


def _resonant() -> Any:
    from test_pipeline import resonant_plant

    return resonant_plant()


@pytest.mark.slow
def test_no_false_alarm_on_the_simulated_motor_over_a_long_run() -> None:
    """80 windows (40 s) of the paper's protocol on the noisy nominal motor and on the
    resonant one: no change reported."""
    from pmsm_sysid.core.physics.plant import load_plant

    noisy = load_plant("plants/nominal_noisy.yaml")
    assert _changes(_simulate(noisy, 21000, seed=11, amplitude_n=50.0)) == []
    assert _changes(_simulate(_resonant(), 21000, seed=12)) == []


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["cogging", "payload"])
def test_a_plant_change_is_reported_within_three_windows(kind: str) -> None:
    """Cogging (plants/cogging.yaml's block) switched on, or 0.5 kg added, at sample 4100:
    the first window holding new data ends at 4250; the change is reported by 4750."""
    from dataclasses import replace

    from pmsm_sysid.core.physics.plant import load_plant

    plant = _resonant()
    after = (plant.with_effects(cogging=load_plant("plants/cogging.yaml").cogging)
             if kind == "cogging" else replace(plant, mass_kg=plant.mass_kg + 0.5))
    found = _changes(_simulate(plant, 6000, seed=5, change_at=4100, after=after))
    assert found and 4250 <= found[0] <= 4750, found
    assert len(found) == 1
