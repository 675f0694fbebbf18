"""Change detection on the stream of window models (pure numpy).

Each fitted window yields a few scalar *features* (:mod:`.tracker` computes them: the
out-of-sample error of the previous model on the newest samples, the new model's own fit,
the distance between consecutive term sets, the first-order GFRF at the excitation
frequency, the output's harmonic content). On a stationary plant these wander within a
spread of their own; a plant change (cogging switched on, a payload added) moves them beyond
it. For every feature a running baseline over the last ``baseline`` windows gives a robust
centre (median) and scale (1.4826 x MAD, never below an absolute and a relative floor), and
the window's robust z-score.

Decision: a change is reported at window j when the combined score S = sqrt(sum z_k^2) over
the window's features (each z clipped to [0, ``z_cap``]: errors count only when they grow)
is >= ``s_confirm`` at both j and j-1: a persistent shift, seen by several features at once
or strongly by one. A single window never decides (every feature has heavy tails: one odd
fit). With six features S is about 2.4 on a stationary plant (median; about 1.5 under
APRBS, whose harmonic content is not observed). After a change the
baselines are cleared; the next ``holdoff`` windows are ignored (they still hold data from
before the change: window/hop - 1 of them) and the following ``warmup`` windows relearn
the baselines (no decision meanwhile), so the new regime becomes the reference; until a
baseline is full again its scale is at least the one from before the change (a few windows
show only part of the excitation's window-to-window spread). A value that
is not finite counts as "no observation" for two-sided features; for one-sided (error-like)
ones, e.g. a diverged free run, it adds ``z_cap`` to S.

Calibration (paper protocol, 1000-sample windows, hop 250, speed and position models, OFR
and iOFR, outputs monitored as :mod:`.tracker` gates them): over eleven stationary stretches
(four runs of 155 windows, the rest before a switch) of the noisy nominal motor (with and
without thrust-sensor noise) and of a motor resonant at 16.5 Hz, S stayed below 5.7 on two
consecutive windows and no change was reported; the largest single-feature z was 15 (the H1
gain of one odd fit among 156), hence no one-window rule. Cogging (plants/cogging.yaml)
switched on was reported 2-3 windows after the first window holding cogging data, 0.5 kg of
payload 2 windows after. ``test/test_change.py`` repeats shorter versions of both.

The baseline holds 48 windows (24 s at hop 250): with window/hop = 4 overlapping windows
per independent stretch of data, 24 windows gave the MAD only about six independent values,
and it came out small often enough to raise false alarms (APRBS, level holds over a 20 s
sequence: its windows differ from each other, and 48 windows span the whole sequence).
``bench/change_false_alarms.py`` counts false alarms over an hour per excitation.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..recording.spectra import welch

MAD_TO_SIGMA = 1.4826
MIN_REFERENCE = 3  # values a baseline needs before it scores anything


@dataclass(frozen=True)
class FeatureSpec:
    """One monitored feature: ``one_sided`` features only alarm when they increase."""

    name: str
    one_sided: bool = False
    floor: float = 0.0
    rel_floor: float = 0.0


@dataclass(frozen=True)
class ChangeConfig:
    """Detector settings; defaults are the calibrated ones."""

    baseline: int = 48
    warmup: int = 8
    s_confirm: float = 7.0
    z_cap: float = 20.0
    holdoff: int = 3

    def __post_init__(self) -> None:
        if self.warmup < 3 or self.baseline < self.warmup:
            raise DataError(f"change detector: need 3 <= warmup <= baseline "
                            f"(got {self.warmup}, {self.baseline})")
        if self.holdoff < 0:
            raise DataError(f"change detector: holdoff must be >= 0 (got {self.holdoff})")
        if not (self.s_confirm > 0 and self.z_cap > 0):
            raise DataError(f"change detector: s_confirm and z_cap must be > 0 "
                            f"(got {self.s_confirm}, {self.z_cap})")


@dataclass(frozen=True)
class ChangeDecision:
    """Outcome for one window: ``state`` is ``settling`` (just after a change), ``learning``,
    ``steady``, ``change`` or ``unjudged`` (no feature values given)."""

    seq: int
    state: str
    z: dict[str, float] = field(default_factory=dict)
    values: dict[str, float] = field(default_factory=dict)
    reasons: tuple[str, ...] = ()
    score: float = 0.0

    @property
    def changed(self) -> bool:
        return self.state == "change"

    def to_dict(self) -> dict[str, object]:
        return {"seq": self.seq, "state": self.state, "reasons": list(self.reasons),
                "score": self.score, "z": dict(self.z), "values": dict(self.values)}


class RobustBaseline:
    """Median and MAD-based scale of the last ``size`` finite values."""

    def __init__(self, size: int, floor: float = 0.0, rel_floor: float = 0.0) -> None:
        self._values: deque[float] = deque(maxlen=size)
        self._floor, self._rel = floor, rel_floor
        self._carried = 0.0  # scale kept from before a change, a floor until full again

    def __len__(self) -> int:
        return len(self._values)

    def add(self, value: float) -> None:
        if math.isfinite(value):
            self._values.append(value)

    def clear(self, keep_spread: bool = False) -> None:
        """Forget the values; with ``keep_spread`` their scale stays a floor of the scale until
        the baseline is full again (see :meth:`ChangeDetector.update`)."""
        held = len(self._values) >= MIN_REFERENCE
        self._carried = self.centre_scale()[1] if keep_spread and held else 0.0
        self._values.clear()

    def centre_scale(self) -> tuple[float, float]:
        arr = np.fromiter(self._values, dtype=np.float64)
        med = float(np.median(arr))
        mad = float(np.median(np.abs(arr - med)))
        carried = self._carried if len(arr) < (self._values.maxlen or 0) else 0.0
        return med, max(MAD_TO_SIGMA * mad, self._floor, self._rel * abs(med), carried, 1e-300)

    def z(self, value: float, one_sided: bool) -> float:
        """Robust z-score of ``value`` (signed excess for one-sided features, else |z|);
        +inf for a non-finite one-sided value, NaN for a non-finite two-sided one, and NaN
        while fewer than :data:`MIN_REFERENCE` values are held (a feature observed only under
        some inputs, e.g. the harmonic content, has no reference yet)."""
        if not math.isfinite(value):
            return math.inf if one_sided else math.nan
        if len(self._values) < MIN_REFERENCE:
            return math.nan
        med, scale = self.centre_scale()
        d = (value - med) / scale
        return d if one_sided else abs(d)


class ChangeDetector:
    """Feeds per-window features into robust baselines and applies the decision rule."""

    def __init__(self, features: Sequence[FeatureSpec],
                 config: ChangeConfig | None = None) -> None:
        if not features:
            raise DataError("change detector needs at least one feature")
        self.config = config or ChangeConfig()
        self.features = {f.name: f for f in features}
        self._base = {f.name: RobustBaseline(self.config.baseline, f.floor, f.rel_floor)
                      for f in features}
        self._prev_score = 0.0
        self._since_reset = 0
        self._settle = 0
        self.events: deque[ChangeDecision] = deque(maxlen=100)  # the latest changes

    def update(self, seq: int, values: Mapping[str, float]) -> ChangeDecision:
        """Judge window ``seq`` from its feature ``values`` (unknown names are ignored)."""
        vals = {k: float(values[k]) for k in self.features if k in values}
        cfg = self.config
        if not vals:  # nothing judged this window: the next one is not "consecutive"
            self._prev_score = 0.0
            return ChangeDecision(seq, "unjudged")
        if self._settle > 0:
            self._settle -= 1
            return ChangeDecision(seq, "settling", values=vals)
        if self._since_reset < cfg.warmup:
            self._learn(vals)
            return ChangeDecision(seq, "learning", values=vals)
        z = {k: self._base[k].z(v, self.features[k].one_sided) for k, v in vals.items()}
        score = combined_score(z, cfg.z_cap)
        persistent = score >= cfg.s_confirm and self._prev_score >= cfg.s_confirm
        self._prev_score = score
        if persistent:
            reasons = _leading(z)
            self.reset(keep_spread=True)
            self._settle = cfg.holdoff
            decision = ChangeDecision(seq, "change", z, vals, reasons, score)
            self.events.append(decision)
            return decision
        self._learn(vals)
        return ChangeDecision(seq, "steady", z, vals, score=score)

    def reset(self, keep_spread: bool = False) -> None:
        """Forget the baselines (after a change, or when the caller restarts the stream).
        After a change (``keep_spread``) the old spreads stay floors of the new scales until
        the baselines are full again: a plant change moves the features' centres, while their
        window-to-window spread is set by the excitation and the noise, and a few windows of
        warm-up show only part of it (under APRBS 8 windows are 4 s of a 20 s sequence)."""
        for b in self._base.values():
            b.clear(keep_spread)
        self._prev_score = 0.0
        self._since_reset = 0

    def _learn(self, vals: Mapping[str, float]) -> None:
        for k, v in vals.items():
            self._base[k].add(v)
        self._since_reset += 1


def combined_score(z: Mapping[str, float], cap: float) -> float:
    """Root sum of squares of the window's z-scores, each clipped to [0, cap] (a diverged
    free run, z = inf, counts as ``cap``; features without a value are skipped)."""
    return math.sqrt(sum(min(max(v, 0.0), cap) ** 2 for v in z.values() if not math.isnan(v)))


def _leading(z: Mapping[str, float], n: int = 3) -> tuple[str, ...]:
    """The ``n`` features with the largest z (the main contributors to the score)."""
    ranked = sorted((k for k, v in z.items() if not math.isnan(v)), key=lambda k: -z[k])
    return tuple(ranked[:n])


def jaccard_distance(a: Iterable[str], b: Iterable[str]) -> float:
    """1 - |A ∩ B| / |A ∪ B| of two term-name sets (0 = same terms, 1 = disjoint)."""
    sa, sb = set(a), set(b)
    union = sa | sb
    return 0.0 if not union else 1.0 - len(sa & sb) / len(union)


#: Windows are compared only under the same excitation: the Bhattacharyya overlap of their
#: input spectra with the reference window's must reach this (1 = same spectrum). Measured
#: over 120 s of each packaged excitation (1000-sample windows, hop 250, 500 Hz): the single
#: tones, multisine, broadband, PRBS and APRBS never fall below 0.97; under the 10 s chirp
#: sweep only the windows at the reference's phase of the sweep reach it (one in 20; the
#: neighbours, one hop away, reach 0.935).
SAME_EXCITATION = 0.95


def input_spectrum(u: NDArray[np.float64], nperseg: int = 128) -> NDArray[np.float64]:
    """Welch power spectrum of ``u`` without its mean, normalised to sum 1 (flat if zero)."""
    x = np.asarray(u, dtype=np.float64)
    _, p = welch(x - x.mean(), nperseg=min(nperseg, len(x)))
    total = float(np.sum(p))
    if not (total > 0 and math.isfinite(total)):
        return np.full(len(p), 1.0 / len(p))
    out: NDArray[np.float64] = p / total
    return out


def spectral_overlap(p: NDArray[np.float64], q: NDArray[np.float64]) -> float:
    """Bhattacharyya coefficient of two normalised spectra (1 = identical, 0 = disjoint)."""
    if len(p) != len(q):
        return 0.0
    return float(np.sum(np.sqrt(np.clip(p, 0.0, None) * np.clip(q, 0.0, None))))
