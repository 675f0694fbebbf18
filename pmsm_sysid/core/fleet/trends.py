"""Per-axis trends of the fitted plant parameters and the drift alarms.

For each axis, the recordings are taken in time order (their first stamp). The **baseline**
of a parameter is its value over the axis's first ``baseline`` recordings (default 8): the
median ``m``, and the spread ``σ_b``, the standard deviation of the n baseline values kept:
all, or all but one odd one (a single value further than ``OUTLIER_MADS`` scaled median
absolute deviations from the median; one odd recording moves neither). A later recording
whose fit states the standard error ``s`` is **in band** when

    |value - m| <= max(sqrt((t σ_b)² (1 + π/(2n)) + (z s)²), min_change |m|)

``z`` (default 4) sets the false-alarm level of one comparison, p = 6e-5 two-sided; ``t``
is Student's quantile at the same level for n - 1 degrees of freedom: a spread measured on a
few recordings is uncertain, and is widened accordingly (t = 8.5 for 8 recordings), and
π/(2n) is the variance of the baseline median itself. The stated errors of the fits are
trusted for the recording's own part only, not for the scatter between days, which real
drives have beyond it (a model error makes stated errors too small, too).
``min_change`` (default 2 %) is the smallest change worth a maintenance alarm, however well
measured. Leaving the band is an **alarm**, raised at the first recording of each excursion
(the answer to "since when"); the parameter's state is ``alarm`` while its latest recording
is out of band.

An effect that is absent counts as size zero (its magnitude parameter: ``cogging.amplitude_n``,
``coulomb_friction.amplitude_n``, ...): a cogging absent from the baseline and found now is
an alarm, so is one that vanished. Its other parameters (a pitch, a Stribeck velocity) are
compared only when the effect is in most of the baseline and in the recording. Phases are
not followed (an angle wraps, and depends on where the scale's zero is).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..errors import OptionError
from .columns import magnitude_of, trended_parameters

#: The spread (σ_b) leaves out baseline values further than this many scaled MADs (1.4826 x
#: the median absolute deviation) from the median.
OUTLIER_MADS = 4.0
MAD_SCALE = 1.4826


@dataclass(frozen=True)
class TrendOptions:
    """``baseline``: how many first recordings of an axis make its baseline (>= 3);
    ``z``: band half-width in standard deviations; ``min_change``: the smallest relative
    change alarmed."""

    baseline: int = 8
    z: float = 4.0
    min_change: float = 0.02

    def __post_init__(self) -> None:
        if isinstance(self.baseline, bool) or not isinstance(self.baseline, int) \
                or self.baseline < 3:
            raise OptionError(f"baseline must be an integer >= 3, got {self.baseline!r}")
        if not (math.isfinite(self.z) and self.z > 0):
            raise OptionError(f"z must be a positive number, got {self.z!r}")
        if not (math.isfinite(self.min_change) and 0 <= self.min_change < 1):
            raise OptionError(f"min_change must be in [0, 1), got {self.min_change!r}")


@dataclass(frozen=True)
class Observation:
    """One analysed recording of an axis: parameter -> value and standard error (None where
    the effect was not found or no error was stated). ``start_time`` in s since 1970 (UTC)."""

    axis: str
    recording: str
    start_time: float
    values: Mapping[str, float | None]
    stds: Mapping[str, float | None]


@dataclass(frozen=True)
class Point:
    """One recording on a parameter's trend; ``lo``/``hi`` is its band (None: no band)."""

    recording: str
    start_time: float
    value: float
    std: float | None
    lo: float | None
    hi: float | None
    baseline: bool
    out: bool


@dataclass(frozen=True)
class Alarm:
    """A parameter left its band: at ``recording`` (the first of the excursion)."""

    axis: str
    parameter: str
    recording: str
    start_time: float
    value: float
    baseline: float
    band: tuple[float, float]


@dataclass(frozen=True)
class ParameterTrend:
    """A parameter of one axis over time. ``state``: ``baseline`` (fewer recordings than the
    baseline needs), ``ok``, ``alarm`` (the latest recording is out of band) or ``untracked``
    (an effect parameter whose effect is not in most of the baseline)."""

    axis: str
    parameter: str
    baseline: float | None
    spread: float | None
    points: tuple[Point, ...]
    alarms: tuple[Alarm, ...]
    state: str

    @property
    def latest(self) -> Point | None:
        return self.points[-1] if self.points else None


@dataclass(frozen=True)
class AxisTrend:
    """Every followed parameter of one axis; ``state`` is ``baseline``, ``ok`` or ``alarm``."""

    axis: str
    recordings: int
    parameters: tuple[ParameterTrend, ...]
    state: str

    @property
    def alarms(self) -> tuple[Alarm, ...]:
        return tuple(a for p in self.parameters for a in p.alarms)

    @property
    def in_alarm(self) -> tuple[ParameterTrend, ...]:
        return tuple(p for p in self.parameters if p.state == "alarm")


def robust_baseline(values: Sequence[float]) -> tuple[float, float, int]:
    """(median, spread, n) of baseline values. The spread is the standard deviation of the n
    values kept: all, or all but one odd one -- a single value further than
    :data:`OUTLIER_MADS` scaled MADs from the median (when several are that far, none is odd:
    the values scatter that much). 0 for fewer than two values."""
    x = np.asarray(values, dtype=np.float64)
    m = float(np.median(x))
    far = np.abs(x - m) > OUTLIER_MADS * MAD_SCALE * float(np.median(np.abs(x - m)))
    keep = x[~far] if int(far.sum()) == 1 else x
    spread = float(np.std(keep, ddof=1)) if len(keep) >= 2 else 0.0
    return m, spread, len(keep)


def spread_factor(n: int, z: float) -> float:
    """``t * sqrt(1 + π/(2n))``: Student's quantile for n baseline values (n - 1 degrees of
    freedom) at the two-sided level of ``z`` standard deviations, for a new value compared
    with the baseline's median (whose variance is about π/(2n) times one value's)."""
    p = 2.0 * float(stats.norm.sf(z))
    return float(stats.t.ppf(1.0 - p / 2.0, max(n - 1, 1))) * math.sqrt(
        1.0 + math.pi / (2.0 * max(n, 1)))


def _series(obs: Sequence[Observation], parameter: str) -> list[tuple[Observation, float | None,
                                                                       float | None]]:
    """(observation, value, std) in time order; an absent effect's magnitude is 0."""
    zero = magnitude_of(parameter)
    out = []
    for o in obs:
        v = o.values.get(parameter)
        s = o.stds.get(parameter)
        s = s if s is not None and math.isfinite(s) and s >= 0 else None
        if v is None and zero:
            v, s = 0.0, None
        out.append((o, v, s))
    return out


def _half_width(m: float, spread: float, s: float | None, s_ref: float,
                options: TrendOptions) -> float:
    """``spread`` here is already widened by :func:`spread_factor`."""
    sd = s if s is not None else s_ref
    return max(math.hypot(spread, options.z * sd), options.min_change * abs(m))


def parameter_trend(obs: Sequence[Observation], parameter: str,
                    options: TrendOptions) -> ParameterTrend | None:
    """The trend of one parameter over one axis's observations (time-ordered); None when
    the axis never had it."""
    series = _series(obs, parameter)
    if all(v is None for _, v, _ in series) or (
            magnitude_of(parameter) and all(o.values.get(parameter) is None for o in obs)):
        return None
    axis = obs[0].axis
    k = options.baseline
    base = [(v, s) for _, v, s in series[:k] if v is not None]
    if len(obs) < k or 2 * len(base) <= k:
        bare = tuple(Point(o.recording, o.start_time, v, s, None, None, i < k, False)
                     for i, (o, v, s) in enumerate(series) if v is not None)
        return ParameterTrend(axis, parameter, None, None, bare, (),
                              "baseline" if len(obs) < k else "untracked")
    m, spread, n = robust_baseline([v for v, _ in base])
    wide = spread * spread_factor(n, options.z)
    stds = [s for _, s in base if s is not None]
    s_ref = float(np.median(stds)) if stds else 0.0
    points: list[Point] = []
    alarms: list[Alarm] = []
    for i, (o, v, s) in enumerate(series):
        if v is None:
            continue
        h = _half_width(m, wide, s, s_ref, options)
        out = i >= k and abs(v - m) > h
        if out and not (points and points[-1].out):
            alarms.append(Alarm(axis, parameter, o.recording, o.start_time, v, m,
                                (m - h, m + h)))
        points.append(Point(o.recording, o.start_time, v, s, m - h, m + h, i < k, out))
    state = "alarm" if points and points[-1].out else "ok"
    return ParameterTrend(axis, parameter, m, spread, tuple(points), tuple(alarms), state)


def axis_trend(obs: Sequence[Observation], options: TrendOptions,
               parameters: Iterable[str] | None = None) -> AxisTrend:
    """Every parameter's trend for one axis's observations (any order)."""
    ordered = sorted(obs, key=lambda o: (o.start_time, o.recording))
    names = trended_parameters() if parameters is None else list(parameters)
    trends = tuple(t for t in (parameter_trend(ordered, p, options) for p in names)
                   if t is not None)
    if len(ordered) < options.baseline:
        state = "baseline"
    else:
        state = "alarm" if any(t.state == "alarm" for t in trends) else "ok"
    axis = ordered[0].axis if ordered else ""
    return AxisTrend(axis, len(ordered), trends, state)


def fleet_trends(observations: Iterable[Observation],
                 options: TrendOptions | None = None) -> tuple[AxisTrend, ...]:
    """The trends of every axis (sorted by axis name)."""
    opts = TrendOptions() if options is None else options
    by_axis: dict[str, list[Observation]] = {}
    for o in observations:
        by_axis.setdefault(o.axis, []).append(o)
    return tuple(axis_trend(by_axis[a], opts) for a in sorted(by_axis))


def fleet_alarms(trends: Iterable[AxisTrend]) -> list[Alarm]:
    """Every alarm of every axis, in time order."""
    return sorted((a for t in trends for a in t.alarms),
                  key=lambda a: (a.start_time, a.axis, a.parameter))
