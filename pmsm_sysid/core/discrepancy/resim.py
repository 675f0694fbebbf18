"""Output error: replay the recorded thrust through a plant over short horizons.

Free-run simulation of a recording is only meaningful open loop: a closed-loop recording
(EMPS) holds its position by feedback, and the open-loop replay of its thrust drifts away
at the first unmodelled newton. So the replay restarts from the measured position and speed
every horizon (the lag state settled, the delay line kept) and the speed error is scored
over every horizon. The plant's noise and quantisation blocks are switched off: the replay
is the model's prediction, not another noisy draw.

**The horizon.** Within a horizon the replayed position drifts from the measured one (thrust
sensor noise and process force integrate twice). A position-periodic force (cogging, thrust
ripple) evaluated at a position that is off by a sizeable fraction of its pitch is a force
at the wrong phase: a *correct* cogging model then adds error instead of removing it (on
``bags/paper_speed_cogging``, 5 N of thrust noise drifts the replay by 2.3 mm rms in 0.25 s,
half the 5 mm pitch, and the true plant replays worse than the nominal one). So the horizon
is the longest (at most ``HORIZON_S``) over which every plant's position-periodic forces
are still evaluated where they act: for components ``A_i sin(k_i x + φ_i)`` and a Gaussian
position error of rms ``s``, a correct model leaves ``Σ A_i² (1 − exp(−k_i² s² / 2))`` of
force energy, against ``Σ A_i² / 2`` left out by a plant without them; the replayed drift
must keep that ratio at or below ``PERIODIC_LEFT`` (5 %, s ≤ p/28 for one sinusoid: the
correct model keeps 95 % of its benefit) at the end of every horizon, and no horizon is
shorter than ``MIN_HORIZON_SAMPLES`` (if the drift exceeds the allowance even there, the
horizon says so: ``resolved`` is false). The drift is measured on the data: each plant is
replayed at ``HORIZON_S`` and its rms position error taken against the age within the
horizon. Plants without position-periodic forces keep ``HORIZON_S``.

**The verdict.** The horizons are independent restarts, so the per-horizon difference of
mean-square speed errors (before − after) gives a z-score: ``better`` (z ≥ ``Z_VERDICT``),
``worse`` (z ≤ −``Z_VERDICT``), ``unresolved`` (the replay cannot tell them apart) or
``same`` (one plant).

A recording used in parts (spans of a long one, ``parts`` = their lengths) is replayed part
by part: every part starts a horizon, and no horizon runs across the gap between two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..physics.motor import MotorSimulator
from ..physics.plant import Plant
from ..recording.signals import Recording
from ..validation.correlation import fit_metrics

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

HORIZON_S = 0.25
PERIODIC_LEFT = 0.05
MIN_HORIZON_SAMPLES = 5
Z_VERDICT = 1.96


@dataclass(frozen=True)
class Replay:
    """Speed (and position) replayed in horizons, the measured speed, and their NRMSE."""

    speed: FloatArray
    measured: FloatArray
    horizon_s: float
    nrmse: float
    position: FloatArray | None = None
    horizon_samples: int = 0
    parts: tuple[int, ...] = ()


def ages(n: int, h: int, parts: tuple[int, ...] = ()) -> IntArray:
    """Samples since the last restart: every ``h`` samples from the start of each part."""
    starts = np.cumsum([0, *(parts or (n,))])[:-1]
    first = np.zeros(n, dtype=np.int64)
    first[starts] = starts
    out: IntArray = (np.arange(n) - np.maximum.accumulate(first)) % h
    return out


def replay(plant: Plant, rec: Recording, horizon_s: float = HORIZON_S,
           parts: tuple[int, ...] = ()) -> Replay:
    """Replay ``rec.thrust`` through ``plant`` (noise off), restarting every horizon."""
    return _replay(plant, rec, max(2, round(horizon_s * rec.sample_rate_hz)), parts)


def _replay(plant: Plant, rec: Recording, h: int, parts: tuple[int, ...] = ()) -> Replay:
    clean = replace(_clean(plant), sample_rate_hz=rec.sample_rate_hz)
    n = len(rec)
    sim = MotorSimulator(clean, seed=0, x0=float(rec.position[0]), v0=float(rec.speed[0]))
    restart = np.flatnonzero(ages(n, h, parts) == 0).tolist()
    speeds, positions = sim.replay(rec.thrust.tolist(), restart, rec.position.tolist(),
                                   rec.speed.tolist())
    out = np.full(n, np.nan)
    pos = np.full(n, np.nan)
    out[:len(speeds)], pos[:len(positions)] = speeds, positions
    if len(speeds) and not math.isfinite(speeds[-1]):
        out[len(speeds) - 1] = pos[len(speeds) - 1] = np.nan
    return Replay(out, rec.speed, h / rec.sample_rate_hz, fit_metrics(rec.speed, out).nrmse,
                  pos, h, parts)


#: replays of one recording (and parts) by the plant as replayed and the horizon in samples
Replays = dict[tuple[Plant, int], Replay]


def kept_replay(plant: Plant, rec: Recording, h: int, parts: tuple[int, ...],
                kept: Replays | None) -> Replay:
    """``_replay`` once per noise-free plant and horizon: ``kept`` holds the replays of this
    recording and these parts (a replay is a function of them alone). The horizon's drift
    replay is the estimation replay of a cogging plant when the horizon stays at its
    maximum: on a simulated cogging recording one replay of five saved (about 0.05 s)."""
    if kept is None:
        return _replay(plant, rec, h, parts)
    key = (_clean(plant), h)
    if key not in kept:
        kept[key] = _replay(plant, rec, h, parts)
    return kept[key]


def periodic_components(plant: Plant, thrust_rms: float) -> list[tuple[float, float]]:
    """(amplitude N, wavenumber rad/m) of the plant's position-periodic forces; a thrust
    ripple's amplitude is its relative size times the rms thrust."""
    out = []
    cog = plant.cogging
    if cog is not None:
        k = 2.0 * math.pi / cog.pitch_m
        out.append((abs(cog.amplitude_n), k))
        out += [(abs(h.amplitude_n), h.order * k) for h in cog.harmonics]
    rip = plant.thrust_ripple
    if rip is not None:
        out.append((abs(rip.relative) * thrust_rms, 2.0 * math.pi / rip.pitch_m))
    return [(a, k) for a, k in out if a > 0 and math.isfinite(k)]


def allowed_drift(components: list[tuple[float, float]], left: float = PERIODIC_LEFT) -> float:
    """Largest rms position error s (m) with Σ A²(1 − exp(−k²s²/2)) ≤ left · Σ A²/2."""
    if not components:
        return math.inf
    amp2 = np.array([a * a for a, _ in components])
    k2 = np.array([k * k for _, k in components])
    target = left * 0.5 * float(amp2.sum())

    def excess(s: float) -> float:
        return float(amp2 @ -np.expm1(-0.5 * k2 * s * s)) - target

    lo, hi = 0.0, 10.0 / math.sqrt(float(k2.min()))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(mid) <= 0 else (lo, mid)
    return lo


def drift_profile(rp: Replay, rec: Recording) -> FloatArray:
    """Rms position error of a replay against the age within its horizon (running max)."""
    if rp.position is None:
        raise ValueError("the replay has no position")
    h = rp.horizon_samples
    err = (rp.position - rec.position) ** 2
    age = ages(len(rec), h, rp.parts)
    ok = np.isfinite(err)
    ms = np.array([float(np.mean(err[(age == a) & ok])) if np.any((age == a) & ok)
                   else math.inf for a in range(h)])
    return np.asarray(np.maximum.accumulate(np.sqrt(ms)), dtype=np.float64)


@dataclass(frozen=True)
class Horizon:
    """The replay horizon and why it was chosen."""

    samples: int
    horizon_s: float
    drift_m: float | None      # rms position drift at the end of a horizon (limiting plant)
    allowed_m: float | None    # the drift the periodic forces allow (None: no such force)
    resolved: bool             # False: the drift exceeds the allowance even at the floor

    def reason(self) -> str:
        if self.allowed_m is None:
            return "no position-periodic force in either plant"
        drift = f"{1e3 * self.drift_m:.3g} mm" if self.drift_m is not None else "n/a"
        text = (f"position drift {drift} rms at the end of a horizon, allowed "
                f"{1e3 * self.allowed_m:.3g} mm by the position-periodic forces")
        return text if self.resolved else text + " (exceeded even at the shortest horizon)"

    def to_dict(self) -> dict[str, object]:
        return {"samples": self.samples, "horizon_s": self.horizon_s, "drift_m": self.drift_m,
                "allowed_drift_m": self.allowed_m, "resolved": self.resolved,
                "reason": self.reason()}


def choose_horizon(plants: tuple[Plant, ...], rec: Recording, max_s: float = HORIZON_S,
                   parts: tuple[int, ...] = (), kept: Replays | None = None) -> Horizon:
    """The longest horizon (≤ ``max_s``) over which each plant's periodic forces stay
    within ``PERIODIC_LEFT`` of their energy (module doc), on this recording; the replays
    it makes go into ``kept`` (see :func:`kept_replay`)."""
    fs = rec.sample_rate_hz
    h_max = max(2, round(max_s * fs))
    floor = min(MIN_HORIZON_SAMPLES, h_max)
    thrust_rms = float(np.sqrt(np.mean(rec.thrust ** 2)))
    h, drift, allowed, resolved = h_max, None, None, True
    for plant in dict.fromkeys(_clean(p) for p in plants):
        comps = periodic_components(plant, thrust_rms)
        if not comps:
            continue
        s_max = allowed_drift(comps)
        prof = drift_profile(kept_replay(plant, rec, h_max, parts, kept), rec)
        n_ok = int(np.searchsorted(prof, s_max, side="right"))
        ok = max(n_ok, floor)
        if ok <= h:
            h, allowed = ok, s_max
            drift = float(prof[min(ok, len(prof)) - 1])
            resolved = n_ok >= floor
    return Horizon(h, h / fs, drift, allowed, resolved)


@dataclass(frozen=True)
class ReplayComparison:
    """Two plants replayed on one recording at one horizon, and the verdict."""

    before: Replay
    after: Replay
    horizon: Horizon
    z: float
    verdict: str  # better | worse | unresolved | same

    def to_dict(self) -> dict[str, object]:
        return {"signal": "speed", "horizon_s": self.horizon.horizon_s,
                "nrmse_before": self.before.nrmse, "nrmse_after": self.after.nrmse,
                "z": self.z if math.isfinite(self.z) else None, "verdict": self.verdict,
                "horizon": self.horizon.to_dict()}


def compare(before: Plant, after: Plant, rec: Recording, horizon: Horizon | None = None,
            parts: tuple[int, ...] = (), kept: Replays | None = None) -> ReplayComparison:
    """Replay ``rec`` through both plants at ``horizon`` (default: :func:`choose_horizon`);
    ``kept``: replays of ``rec`` and ``parts`` already made (:func:`kept_replay`)."""
    hz = horizon if horizon is not None else choose_horizon((before, after), rec, parts=parts,
                                                            kept=kept)
    if hz.samples != round(hz.horizon_s * rec.sample_rate_hz):
        hz = replace(hz, samples=max(2, round(hz.horizon_s * rec.sample_rate_hz)))
    rb = kept_replay(before, rec, hz.samples, parts, kept)
    if _clean(after) == _clean(before):
        return ReplayComparison(rb, rb, hz, 0.0, "same")
    ra = kept_replay(after, rec, hz.samples, parts, kept)
    z = _paired_z(rb.speed, ra.speed, rec.speed, hz.samples, parts)
    verdict = "better" if z >= Z_VERDICT else "worse" if z <= -Z_VERDICT else "unresolved"
    return ReplayComparison(rb, ra, hz, z, verdict)


def _clean(plant: Plant) -> Plant:
    """The plant as the replay sees it (no noise, no quantisation)."""
    return replace(plant, noise=None, quantisation=None)


def _paired_z(before: FloatArray, after: FloatArray, measured: FloatArray, h: int,
              parts: tuple[int, ...] = ()) -> float:
    """z of the mean per-horizon drop in mean-square speed error (horizons independent;
    only whole horizons count)."""
    group = np.cumsum(ages(len(measured), h, parts) == 0) - 1
    size = np.bincount(group)
    whole = size[group] == h
    if int(np.count_nonzero(size == h)) < 2:
        return 0.0
    keep = np.flatnonzero(size == h)

    def per_horizon(sim: FloatArray) -> FloatArray:
        sq = (sim - measured) ** 2
        out: FloatArray = np.bincount(group[whole], weights=sq[whole],
                                      minlength=len(size))[keep] / h
        return out

    eb, ea = per_horizon(before), per_horizon(after)
    d = eb - ea
    if not np.all(np.isfinite(d)):
        return -math.inf if not np.all(np.isfinite(ea)) else math.inf
    sd = float(np.std(d, ddof=1))
    mean = float(np.mean(d))
    if sd == 0.0:
        return 0.0 if mean == 0.0 else math.copysign(math.inf, mean)
    return mean / (sd / math.sqrt(len(d)))
