"""Per-axis trends and drift alarms (pure, no Dask): the baseline shrugs off an odd
recording, a stable axis with honest noise stays quiet over many recordings, and a change
(a step, a creep, an effect that appears or vanishes) is alarmed at the recording where it
leaves the band -- once per excursion. The table's columns follow the plant file's effects."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from pmsm_sysid.core.errors import OptionError
from pmsm_sysid.core.fleet import (
    EFFECT_PARAMS,
    MAGNITUDE,
    Observation,
    TrendOptions,
    columns,
    diagnosis_columns,
    fleet_alarms,
    fleet_trends,
    plant_columns,
    robust_baseline,
    spread_factor,
    trended_parameters,
)
from pmsm_sysid.core.physics.plant import EFFECT_BLOCKS, load_plant, plant_to_dict

REPO = Path(__file__).resolve().parents[1]
DAY = 86400.0
T0 = 1.7e9


def _obs(axis: str, i: int, values: dict[str, float | None],
         stds: dict[str, float | None] | None = None) -> Observation:
    return Observation(axis, f"{axis}/rec{i:03d}", T0 + i * DAY, values, stds or {})


def _axis(axis: str, truth: list[dict[str, float | None]], stds: dict[str, float],
          seed: int, extra_scatter: float = 0.0) -> list[Observation]:
    """Observations of ``truth`` (one dict per recording) measured with the stated standard
    errors (plus ``extra_scatter`` x std of recording-to-recording variation)."""
    rng = np.random.default_rng(seed)
    out = []
    for i, true in enumerate(truth):
        values, errs = {}, {}
        for p, v in true.items():
            if v is None:
                values[p] = errs[p] = None
                continue
            s = stds[p]
            values[p] = v + rng.normal(0, s * math.hypot(1.0, extra_scatter))
            errs[p] = s * rng.uniform(0.8, 1.2)  # each fit states its own error
        out.append(_obs(axis, i, values, errs))
    return out


STDS = {"mass_kg": 0.006, "viscous_n_per_mps": 0.3, "coulomb_friction.amplitude_n": 0.03,
        "cogging.amplitude_n": 0.03, "cogging.pitch_m": 2e-5}
BASE = {"mass_kg": 2.3213, "viscous_n_per_mps": 32.5, "coulomb_friction.amplitude_n": 5.0}


def test_the_baseline_shrugs_off_one_odd_recording() -> None:
    m, s, n = robust_baseline([5.0, 5.02, 4.98, 5.01, 9.0])
    assert m == 5.01 and s == pytest.approx(np.std([5.0, 5.02, 4.98, 5.01], ddof=1))
    assert n == 4
    # two values that far are not one odd one: the values scatter, and the spread says so
    m, s, n = robust_baseline([5.0, 5.02, 4.98, 5.01, 9.0, 1.0])
    assert n == 6 and s == pytest.approx(np.std([5.0, 5.02, 4.98, 5.01, 9.0, 1.0], ddof=1))
    m, s, n = robust_baseline([0.0, 0.0, 0.0, 0.0, 0.7])  # an effect found once of five
    assert (m, s, n) == (0.0, 0.0, 4)


def test_the_spread_is_widened_by_students_quantile() -> None:
    """Independent check of the factor against tabulated t quantiles (p = 6.33e-5)."""
    assert spread_factor(8, 4.0) == pytest.approx(8.467 * math.sqrt(1 + math.pi / 16),
                                                  rel=1e-3)
    assert spread_factor(40, 4.0) == pytest.approx(4.42 * math.sqrt(1 + math.pi / 80),
                                                   rel=2e-2)
    assert spread_factor(10**6, 4.0) == pytest.approx(4.0, rel=1e-3)  # the normal limit


@pytest.mark.parametrize("extra_scatter", [0.0, 1.0, 4.0])
def test_a_stable_axis_is_quiet_over_many_recordings(extra_scatter: float) -> None:
    """500 stable axes of 48 recordings each (3 parameters, 120 000 comparisons), with
    honest standard errors, then day-to-day variation as large as the estimation error, then
    four times larger than the fits state (errors understated, as a model error does)."""
    options = TrendOptions()
    alarmed = 0
    for seed in range(500):
        obs = _axis("a", [dict(BASE)] * 48, STDS, seed, extra_scatter=extra_scatter)
        trends = fleet_trends(obs, options)
        assert trends[0].state in ("ok", "alarm")
        alarmed += bool(fleet_alarms(trends))
    assert alarmed <= 5, alarmed


@pytest.mark.parametrize(("parameter", "factor"), [
    ("coulomb_friction.amplitude_n", 1.3), ("mass_kg", 1.05),
    ("viscous_n_per_mps", 1.15), ("coulomb_friction.amplitude_n", 0.7)])
def test_a_step_is_alarmed_at_the_recording_where_it_happens(parameter: str,
                                                            factor: float) -> None:
    truth = [dict(BASE) for _ in range(12)]
    for t in truth[8:]:
        t[parameter] = BASE[parameter] * factor
    for seed in range(20):
        alarms = fleet_alarms(fleet_trends(_axis("a", truth, STDS, seed)))
        assert [(a.parameter, a.recording) for a in alarms] == [(parameter, "a/rec008")]
        a = alarms[0]
        assert a.start_time == T0 + 8 * DAY and a.band[0] < a.baseline < a.band[1]
        assert not a.band[0] <= a.value <= a.band[1]
        assert a.baseline == pytest.approx(BASE[parameter], rel=0.01)


def test_a_creep_is_alarmed_once_where_it_leaves_the_band_and_stays_in_alarm() -> None:
    """Coulomb friction creeping up 3 % per recording after the baseline (a rail running
    dry), to +30 %: one alarm, at the first recording beyond the band; state alarm."""
    truth = [dict(BASE) for _ in range(18)]
    for i, t in enumerate(truth[8:], start=1):
        t["coulomb_friction.amplitude_n"] = 5.0 * (1 + 0.03 * i)
    for seed in range(20):
        (trend,) = fleet_trends(_axis("a", truth, STDS, seed))
        coulomb = {p.parameter: p for p in trend.parameters}["coulomb_friction.amplitude_n"]
        first_out = next(i for i, p in enumerate(coulomb.points) if p.out)
        # the band is 2 % of 5 N (min_change) or about 9.5 x 0.03 N: the first out is
        # +3 % (recording 8) or, by noise or a wider band, +6 % or +9 %
        assert first_out in (8, 9, 10), first_out
        assert [a.recording for a in coulomb.alarms] == [f"a/rec{first_out:03d}"]
        assert coulomb.state == "alarm" and trend.state == "alarm"
        assert [p.parameter for p in trend.in_alarm] == ["coulomb_friction.amplitude_n"]


def test_an_effect_that_appears_or_vanishes_is_an_alarm() -> None:
    truth = [dict(BASE) for _ in range(12)]
    for t in truth[9:]:
        t["cogging.amplitude_n"], t["cogging.pitch_m"] = 1.0, 0.005
    alarms = fleet_alarms(fleet_trends(_axis("a", truth, STDS, 1)))
    assert [(a.parameter, a.recording, a.baseline) for a in alarms] == [
        ("cogging.amplitude_n", "a/rec009", 0.0)]  # the pitch has no baseline: no alarm
    gone = [dict(BASE, **{"cogging.amplitude_n": 1.0, "cogging.pitch_m": 0.005})
            for _ in range(10)]
    for t in gone[8:]:
        t["cogging.amplitude_n"] = t["cogging.pitch_m"] = None
    alarms = fleet_alarms(fleet_trends(_axis("b", gone, STDS, 2)))
    assert [(a.parameter, a.recording, a.value) for a in alarms] == [
        ("cogging.amplitude_n", "b/rec008", 0.0)]


def test_an_effect_found_once_in_the_baseline_is_an_odd_one_not_the_baseline() -> None:
    truth = [dict(BASE) for _ in range(10)]
    truth[2]["cogging.amplitude_n"] = 0.5
    (trend,) = fleet_trends(_axis("a", truth, STDS, 3))
    cog = {p.parameter: p for p in trend.parameters}["cogging.amplitude_n"]
    assert cog.baseline == 0.0 and cog.state == "ok" and not cog.alarms
    pitch = {p.parameter: p for p in trend.parameters}.get("cogging.pitch_m")
    assert pitch is None  # never found: not followed


def test_each_excursion_is_one_alarm_and_a_return_clears_the_state() -> None:
    truth = [dict(BASE) for _ in range(14)]
    for i in (8, 9, 12):
        truth[i]["mass_kg"] = BASE["mass_kg"] * 1.1
    (trend,) = fleet_trends(_axis("a", truth, STDS, 4))
    mass = {p.parameter: p for p in trend.parameters}["mass_kg"]
    assert [a.recording for a in mass.alarms] == ["a/rec008", "a/rec012"]
    assert mass.state == "ok" and trend.state == "ok"


def test_a_baseline_still_forming_raises_nothing() -> None:
    obs = _axis("a", [dict(BASE)] * 6 + [dict(BASE, mass_kg=9.0)], STDS, 5)
    (trend,) = fleet_trends(obs, TrendOptions(baseline=8))
    assert trend.state == "baseline" and not trend.alarms
    assert all(p.lo is None for t in trend.parameters for p in t.points)


def test_the_band_is_never_narrower_than_the_smallest_change_worth_an_alarm() -> None:
    """Perfectly repeatable data (no spread, tiny errors): +1 % is noise for maintenance,
    +3 % is not."""
    obs = [_obs("a", i, {"mass_kg": 2.0}, {"mass_kg": 1e-6}) for i in range(8)]
    obs += [_obs("a", 8, {"mass_kg": 2.02}, {"mass_kg": 1e-6}),
            _obs("a", 9, {"mass_kg": 2.06}, {"mass_kg": 1e-6})]
    (trend,) = fleet_trends(obs, TrendOptions(min_change=0.02))
    assert [a.recording for a in trend.alarms] == ["a/rec009"]
    assert trend.alarms[0].band == pytest.approx((1.96, 2.04))


def test_the_band_combines_the_spread_and_the_stated_error() -> None:
    values = [10.0, 10.2, 9.8, 10.1, 9.9]
    obs = [_obs("a", i, {"mass_kg": v}, {"mass_kg": 0.05}) for i, v in enumerate(values)]
    obs.append(_obs("a", 5, {"mass_kg": 10.0}, {"mass_kg": 0.3}))
    (trend,) = fleet_trends(obs, TrendOptions(baseline=5, z=4.0, min_change=0.0))
    last = trend.parameters[0].points[-1]
    spread = float(np.std(values, ddof=1))
    # Student's t at p = 6.33e-5 with 4 degrees of freedom: 17.45 (tables)
    widened = spread * 17.448 * math.sqrt(1 + math.pi / 10)
    assert last.hi - 10.0 == pytest.approx(math.hypot(widened, 4.0 * 0.3), rel=1e-4)


def test_axes_are_followed_each_on_its_own() -> None:
    a = _axis("/a", [dict(BASE)] * 10, STDS, 6)
    b_truth = [dict(BASE) for _ in range(10)]
    b_truth[9]["mass_kg"] = 2.5
    b = _axis("/b", b_truth, STDS, 7)
    interleaved = [o for pair in zip(b, a, strict=True) for o in pair]
    trends = fleet_trends(interleaved)
    assert [t.axis for t in trends] == ["/a", "/b"]
    assert [t.state for t in trends] == ["ok", "alarm"]
    assert [(x.axis, x.recording) for x in fleet_alarms(trends)] == [("/b", "/b/rec009")]


@pytest.mark.parametrize("bad", [dict(baseline=2), dict(baseline=True), dict(z=0.0),
                                 dict(z=float("nan")), dict(min_change=1.0),
                                 dict(min_change=-0.1)])
def test_trend_options_are_checked(bad: dict[str, float]) -> None:
    with pytest.raises(OptionError):
        TrendOptions(**bad)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------- columns


def test_every_effect_of_the_plant_file_has_its_columns() -> None:
    blocks = {k: v for k, v in EFFECT_BLOCKS.items() if k not in ("noise", "quantisation")}
    assert set(EFFECT_PARAMS) == set(blocks) == set(MAGNITUDE)
    for name, cls in blocks.items():
        fields = [f.name for f in dataclasses.fields(cls) if f.name != "smoothing_mps"]
        assert list(EFFECT_PARAMS[name]) == fields, name
        assert MAGNITUDE[name] in fields
    cols = columns()
    assert len(cols) == len(set(cols))
    assert cols[:7] == ["recording", "axis", "start_time", "duration_s", "sample_rate_hz",
                        "status", "error"]
    for name, params in EFFECT_PARAMS.items():
        for p in params:
            assert f"{name}.{p}" in cols and f"{name}.{p}.std" in cols
        assert f"{name}.confidence" in cols
    assert {"mass_kg", "viscous_n_per_mps", "nrmse_before", "nrmse_after"} <= set(cols)
    assert not [p for p in trended_parameters() if p.endswith(("phase_rad", "harmonics"))]


def test_a_plant_becomes_its_columns() -> None:
    plant = plant_to_dict(load_plant(REPO / "plants" / "all_effects.yaml"))
    std = {"mass_kg": 0.01, "coulomb_friction": {"amplitude_n": 0.2},
           "cogging": {"amplitude_n": 0.1, "harmonic_2_amplitude_n": 0.05}}
    effects = [{"name": "coulomb_friction", "confidence": "high"},
               {"name": "cogging", "confidence": "moderate"}]
    row = plant_columns(plant, std, effects)
    assert row["mass_kg"] == 2.3213 and row["mass_kg.std"] == 0.01
    assert row["viscous_n_per_mps"] == 32.4992 and row["viscous_n_per_mps.std"] is None
    assert row["coulomb_friction.amplitude_n"] == 2.0
    assert row["coulomb_friction.amplitude_n.std"] == 0.2
    assert row["coulomb_friction.confidence"] == "high"
    assert row["cogging.confidence"] == "moderate" and row["spring.confidence"] is None
    assert row["thrust_lag.tau_s"] == pytest.approx(0.0016 / 3.8835)
    assert row["cogging.harmonics"] == [
        {"order": 2, "amplitude_n": 1.0, "phase_rad": 0.0},
        {"order": 3, "amplitude_n": 0.3, "phase_rad": 1.2}]
    assert row["cogging.harmonics.std"] == [
        {"order": 2, "amplitude_n": 0.05, "phase_rad": None},
        {"order": 3, "amplitude_n": None, "phase_rad": None}]
    assert row["spring.stiffness_n_per_m"] == 20.0
    absent = plant_columns({"mass_kg": 2.0, "viscous_n_per_mps": 30.0}, {}, [])
    assert absent["cogging.amplitude_n"] is None and absent["cogging.harmonics"] is None


def test_the_diagnosis_gives_the_fit_before_and_after_on_held_out_data() -> None:
    d = {"fit": {"estimation": {"nrmse_before": 0.5, "nrmse_after": 0.1},
                 "validation": {"nrmse_before": 0.6, "nrmse_after": 0.2}},
         "effects": [{"name": "coulomb_friction"}]}
    assert diagnosis_columns(d) == {"nrmse_before": 0.6, "nrmse_after": 0.2,
                                    "diagnosed": ["coulomb_friction"]}


def test_date_ticks_are_found_once_per_view_as_matplotlib_finds_them(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from datetime import UTC, datetime

    from matplotlib.dates import AutoDateLocator, date2num
    from matplotlib.figure import Figure

    from pmsm_sysid.plots.fleet import SteadyDateLocator

    found = []
    get_locator = AutoDateLocator.get_locator
    monkeypatch.setattr(AutoDateLocator, "get_locator",
                        lambda self, lo, hi: found.append(lo) or get_locator(self, lo, hi))
    ax = Figure().subplots()
    steady = SteadyDateLocator()
    ax.xaxis.set_major_locator(steady)
    reference = AutoDateLocator()
    reference.set_axis(ax.xaxis)
    for days in (3, 40):
        ax.set_xlim(date2num(datetime(2024, 1, 1, tzinfo=UTC)),
                    date2num(datetime(2024, 1, 1 + days % 28, tzinfo=UTC)) + days // 28 * 28)
        found.clear()
        ticks = [steady() for _ in range(5)]
        assert len(found) == 1  # computed once for this view
        for t in ticks:
            np.testing.assert_array_equal(t, reference())
