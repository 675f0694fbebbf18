"""Equation-error data: the force residual of inverse dynamics, parallel-filtered.

The nominal plant says ``F_eff = M a + B v + F_effects(x, v, F_eff)`` (the sign convention of
:mod:`pmsm_sysid.core.physics.motor`), so the force residual ``r = F - M a - B v - F_effects`` is
exactly the force of whatever the plant leaves out. It needs the acceleration, which is the
reason for the care below (the IDIM-LS practice of the EMPS benchmark):

* **Timing.** The thrust stamped t_k is held over [t_k, t_{k+1}). With a measured
  speed, interval k pairs ``F(k)`` with ``a_k = (v_{k+1} - v_k)/T`` and ``v̄_k`` -- for the
  rigid mass-damper the inversion ``F(k) = c1 v_{k+1} - c0 v_k`` is exact under zero-order
  hold. With position only (speed derived, as in EMPS), sample j pairs the central second
  difference of position with the mean thrust ``(F(j-1) + F(j))/2`` of the two intervals it
  spans.
* **Parallel filtering.** The residual and every regressor go through the same zero-phase
  Butterworth low-pass L (order 4, ``sosfiltfilt``). L is linear and time-invariant, so
  ``L r = Σ θ_i L φ_i`` holds exactly whatever the cut-off: filtering trades noise for
  bandwidth but adds no bias. Nonlinear regressors are evaluated on the smoothed states.
* **Cut-off from the data's bandwidth.** ``fc = 4 · f99`` where f99 is the frequency below
  which 99 % of the power of the (mean-removed) speed lies, clipped to [0.05, 0.2]·fs. The
  motion lives below f99 and the effects it drives at its low harmonics; above a few times
  f99 the residual is differentiated measurement noise, which grows as f². The speed, not
  the thrust, sets the band: under feedback the thrust carries the controller's response
  to sensor noise at all frequencies, and a cut-off that lets it in lets in the noise of
  the acceleration too -- which then biases the mass (errors in variables) and fakes lags.
* **Decimation.** After L, every D-th sample is kept, D = floor(fs / (2.5 fc)), and
  ``ceil(3 fs / fc)`` samples are dropped at each end (filter start-up).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import DiagnoseError
from ..physics.plant import SIGN_SMOOTHING_MPS, Plant
from ..recording.signals import Recording
from ..recording.spans import Parts, as_parts
from .averaging import interval_effects, interval_force, interval_friction, sign_width
from .calibration import SpeedPrior, calibrated_friction
from .feedback import high_band
from .instruments import reading_instruments
from .memo import ContentCache, content_key
from .zerophase import butter_sos, sosfiltfilt, thinned_columns

FloatArray = NDArray[np.float64]

#: Projected columns and friction regressors of the latest recordings (by content).
PROJECTED = ContentCache(32 << 20)
FRICTION = ContentCache(8 << 20)

FILTER_ORDER = 4
POWER_FRACTION = 0.99
CUTOFF_FACTOR = 4.0
MIN_SAMPLES = 200


@dataclass(frozen=True)
class FilterSpec:
    """The parallel filter: Butterworth cut-off, decimation and trimmed edge (samples)."""

    cutoff_hz: float
    band_hz: float
    decimation: int
    edge: int
    order: int = FILTER_ORDER

    def to_dict(self) -> dict[str, float | int | str]:
        return {"cutoff_hz": self.cutoff_hz, "speed_band_hz": self.band_hz,
                "decimation": self.decimation, "edge_samples": self.edge,
                "order": self.order, "kind": "butterworth zero-phase (sosfiltfilt)"}


def choose_filter(speed: FloatArray | Sequence[FloatArray], fs: float) -> FilterSpec:
    """Cut-off from the speed's 99 % power bandwidth (module doc); for the speeds of several
    parts, from their periodograms averaged (each part cut to the shortest)."""
    pieces = [speed] if isinstance(speed, np.ndarray) else list(speed)
    n = min(len(p) for p in pieces)
    power = np.zeros(n // 2 + 1)
    for piece in pieces:
        u = np.asarray(piece[:n], dtype=np.float64) - float(np.mean(piece[:n]))
        power += np.abs(np.fft.rfft(u)) ** 2
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    total = float(power.sum())
    if total <= 0.0:
        raise DiagnoseError("the axis does not move: nothing to compare the plant with")
    hi = freqs > 0.3 * fs
    if hi.sum() >= 8:  # the white measurement-noise floor, read where a servo has no motion
        power = np.maximum(power - float(np.median(power[hi])), 0.0)
        total = float(power.sum())
        if total <= 0.0:
            raise DiagnoseError("the axis does not move above its measurement noise")
    cum = np.cumsum(power) / total
    band = float(freqs[int(np.searchsorted(cum, POWER_FRACTION))])
    fc = min(max(CUTOFF_FACTOR * band, 0.05 * fs), 0.2 * fs)
    decim = max(1, math.floor(fs / (2.5 * fc)))
    edge = math.ceil(3.0 * fs / fc)
    return FilterSpec(cutoff_hz=fc, band_hz=band, decimation=decim, edge=edge)


def _noise_gain(op: FloatArray, sos: FloatArray) -> float:
    """Norm of the filtered impulse response of a finite-difference operator."""
    return float(np.linalg.norm(sosfiltfilt(sos, op)))


def _hf_sigma(sigs: Sequence[FloatArray], fs: float) -> float:
    """White measurement noise of a signal (its parts pooled) read above 0.3 fs (white
    fraction there: 0.4)."""
    return float(np.std(np.concatenate([high_band(s, fs) for s in sigs]))) / math.sqrt(0.4)


def kinematic_mode(rec: Parts, spec: FilterSpec, closed_loop: bool = True) -> str:
    """``position`` when the speed is derived, or under feedback when the acceleration is
    less noisy from the position than from the speed in the filter's band; else ``speed``.

    Acceleration from a noisy speed is an error in a regressor (it biases the mass towards
    zero); a position encoder's noise, differentiated twice but band-limited by the same
    filter, is usually far smaller. Both noises are read above 0.3 fs and carried through
    the exact difference operators and the filter. Open loop the instruments of
    :mod:`.instruments` remove that bias anyway, and the speed's pairing with the held
    thrust is exact (it tells a lag from a delay), so a measured speed is kept.
    """
    parts = as_parts(rec)
    if parts[0].speed_derived:
        return "position"
    if not closed_loop:
        return "speed"
    fs = parts[0].sample_rate_hz
    sos = butter_sos(spec.order, spec.cutoff_hz, fs)
    imp = np.zeros(2049)
    imp[1024] = 1.0
    d1 = fs * (imp[1:] - imp[:-1])
    d2 = fs * fs * (imp[2:] - 2.0 * imp[1:-1] + imp[:-2])
    from_speed = _hf_sigma([r.speed for r in parts], fs) * _noise_gain(d1, sos)
    from_position = _hf_sigma([r.position for r in parts], fs) * _noise_gain(d2, sos)
    return "position" if from_position < from_speed else "speed"


def smoothed_speed_noise(rec: Parts, mode: str, sos: FloatArray) -> float:
    """Standard deviation (m/s) of the measurement noise left in the smoothed speed.

    The raw noise is read above 0.3 fs, where a servo's motion has no power (the white-noise
    fraction there is 0.4), and carried through the exact linear operations that make the
    smoothed speed (interval mean or central difference, then the filter L).
    """
    parts = as_parts(rec)
    fs = parts[0].sample_rate_hz
    sigma = _hf_sigma([r.speed if mode == "speed" else r.position for r in parts], fs)
    imp = np.zeros(2049)
    imp[1024] = 1.0
    op = 0.5 * (imp[1:] + imp[:-1]) if mode == "speed" else 0.5 * fs * (imp[2:] - imp[:-2])
    gain = float(np.linalg.norm(sosfiltfilt(sos, op)))
    return sigma * gain


@dataclass(frozen=True)
class EquationData:
    """One contiguous segment prepared for equation-error regression.

    Full-rate arrays (one per equation instant, see module doc): ``x``, ``v``, ``a`` are the
    smoothed states used as regressor arguments, ``v_lo``/``v_hi`` the smoothed speed at the
    two ends of the sample interval each instant averages over; ``cmd`` is the thrust
    command per interval and ``force`` the nominal plant's applied force paired with each
    instant. ``y`` is the
    filtered, trimmed and decimated residual; ``project`` maps any full-rate column the same
    way, so regressors and residual stay consistent.

    ``parts``: the data of several contiguous recordings (spans of a long one) end to end,
    with the number of recorded samples of each; every filtering, pairing and trimming is
    then done within each part, so the result is the parts' own data, concatenated
    (:func:`.parts.joined`). Empty: one contiguous recording.
    """

    x: FloatArray
    v: FloatArray
    v_lo: FloatArray
    v_hi: FloatArray
    a: FloatArray
    v_raw: FloatArray
    a_raw: FloatArray
    a_iv: FloatArray
    v_iv: FloatArray
    cmd: FloatArray
    force: FloatArray
    y: FloatArray
    t: FloatArray
    period: float
    mode: str
    filt: FilterSpec
    sos: FloatArray
    speed_noise_mps: float = 0.0
    sign_smoothing_mps: float = SIGN_SMOOTHING_MPS
    prior: SpeedPrior | None = None
    parts: tuple[int, ...] = ()
    force_iv: FloatArray | None = None  # force as the thrust a gap away predicts it
    inst: tuple[FloatArray, ...] | None = None  # filtered instruments, a basis per part
    thrust_gap: int = 0  # samples kept between the thrust in a regressor and the instant
    closed_loop: bool = False

    @property
    def n(self) -> int:
        return len(self.y)

    def _bounds(self, offset: int) -> list[tuple[int, int]]:
        """(start, stop) of each part in arrays with ``offset`` fewer entries per part than
        recorded samples (0: per interval, 1 or 2: per equation instant)."""
        sizes = self.parts or (len(self.cmd),)
        edges = np.cumsum([0, *(k - offset for k in sizes)])
        return [(int(a), int(b)) for a, b in itertools.pairwise(edges)]

    def instants(self) -> list[tuple[int, int]]:
        """(start, stop) of each part in the full-rate arrays (one per equation instant)."""
        return self._bounds(1 if self.mode == "speed" else 2)

    def per_interval(self, fn: Callable[[FloatArray], FloatArray],
                     q: FloatArray) -> FloatArray:
        """``fn`` applied to each part of a per-interval array, the results concatenated."""
        arr = np.asarray(q, dtype=np.float64)
        if not self.parts:
            return fn(arr)
        out: FloatArray = np.concatenate([fn(arr[a:b]) for a, b in self._bounds(0)])
        return out

    @property
    def sample_rate_hz(self) -> float:
        """Rate of the regression samples (after decimation)."""
        return 1.0 / (self.period * self.filt.decimation)

    def project(self, col: FloatArray) -> FloatArray:
        """L-filter, trim and decimate a full-rate column (or the columns of a 2-D array).

        A fit projects the same columns for every plant and scan it tries: the results
        are kept by content (:data:`PROJECTED`)."""
        arr = np.asarray(col, dtype=np.float64)
        e, d = self.filt.edge, self.filt.decimation
        bounds = tuple(self.instants()) if self.parts else ()
        key = content_key("project", self.sos, e, d, bounds, arr)
        return PROJECTED.array(key, lambda: projected(self.sos, arr, e, d, bounds))

    def pair(self, per_interval: FloatArray) -> FloatArray:
        """Map a per-interval quantity (mean over [t_k, t_k+1)) to the equation instants."""
        def one(q: FloatArray) -> FloatArray:
            if self.mode == "speed":
                return q[:-1]
            out: FloatArray = 0.5 * (q[:-2] + q[1:-1])
            return out

        return self.per_interval(one, per_interval)

    def friction(self, stribeck_mps: float = 0.0) -> FloatArray:
        """Interval means of sign(v) (or the Stribeck hump) given the smoothed speed:
        calibrated with the speed's own distribution when known (:mod:`.calibration`),
        else with the sign widened by the noise."""
        if self.prior is None:
            return interval_friction(self.v_lo, self.v_hi, self.sign_smoothing_mps,
                                     stribeck_mps)
        p = self.prior
        key = content_key("friction", p.digest(), self.v_lo, self.v_hi,
                          SIGN_SMOOTHING_MPS, float(stribeck_mps))
        return FRICTION.array(key, lambda: calibrated_friction(
            p, self.v_lo, self.v_hi, SIGN_SMOOTHING_MPS, stribeck_mps))

    def forced(self, tau: float = 0.0, delay: float = 0.0) -> FloatArray:
        """Applied force at the equation instants for a lag/delay on the command."""
        return self.pair(self.per_interval(
            lambda c: interval_force(c, self.period, tau, delay), self.cmd))

    @property
    def v_axis(self) -> FloatArray:
        """The speed as an axis for curves over velocity: open loop the instrumented one
        (:attr:`v_iv`); the smoothed speed holds the speed sensor's noise and the process
        force of the interval, both in the residual too (a spline over it found
        significance 15 in pure noise: a 16.5 Hz tone, 5 mm/s of speed noise)."""
        return self.v if self.closed_loop else self.v_iv

    @property
    def regressor_force(self) -> FloatArray:
        """``force`` in the regressors that multiply it by the state (the ripple): under a
        noisy reading or feedback the one the thrust a gap away predicts."""
        return self.force if self.force_iv is None else self.force_iv

    @property
    def thrust_axis(self) -> FloatArray:
        """``force`` as an axis for curves: under a noisy reading the predicted one."""
        return self.force if self.thrust_gap == 0 else self.regressor_force

    def instrument(self, cols: FloatArray) -> FloatArray:
        """Filtered columns projected on each part's instruments under a noisy reading
        (the first stage of two-stage least squares); unchanged otherwise."""
        if self.inst is None:
            return cols
        edges = itertools.pairwise(np.cumsum([0, *(len(q) for q in self.inst)]))
        out: FloatArray = np.concatenate([q @ (q.T @ cols[a:b]) for q, (a, b)
                                          in zip(self.inst, edges, strict=True)])
        return out


def projected(sos: FloatArray, arr: FloatArray, e: int, d: int,
               bounds: tuple[tuple[int, int], ...]) -> FloatArray:
    """``arr`` zero-phase filtered, ``e`` samples trimmed at each end and every ``d``-th
    kept: as one, or per part (``bounds``, rows of ``arr``) and the parts joined."""
    if not bounds:
        return thinned_columns(sos, arr, e, d)
    return np.concatenate([thinned_columns(sos, arr[a:b], e, d) for a, b in bounds])


def _nominal_dynamics(plant: Plant, rec: Recording, mode: str) -> tuple[FloatArray, ...]:
    """(x, v, a, M a + B v exact) at the equation instants of ``mode`` (module doc)."""
    T = 1.0 / rec.sample_rate_hz
    m, b = plant.mass_kg, plant.viscous_n_per_mps
    x = rec.position
    if mode == "speed":
        v = rec.speed
        a = np.diff(v) / T
        beta = b * T / m
        if beta > 1e-9:
            alpha = math.exp(-beta)
            c1, c0 = b / (1 - alpha), b * alpha / (1 - alpha)
        else:
            c1 = c0 = m / T
        inertial = c1 * v[1:] - c0 * v[:-1]
        return 0.5 * (x[1:] + x[:-1]), 0.5 * (v[1:] + v[:-1]), a, inertial
    vbar = np.diff(x) / T
    a = np.diff(vbar) / T
    vc = 0.5 * (vbar[1:] + vbar[:-1])
    return x[1:-1], vc, a, m * a + b * vc


def _interval_ends(rec: Recording, mode: str, sos: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Smoothed speed at the start and end of the interval each equation instant covers."""
    if mode == "speed":
        vs = sosfiltfilt(sos, rec.speed)
        return vs[:-1], vs[1:]
    vbar = sosfiltfilt(sos, np.diff(rec.position) * rec.sample_rate_hz)
    return vbar[:-1], vbar[1:]


def _applied(cmd: FloatArray, period: float, tau: float, delay: float,
             mode: str) -> FloatArray:
    """The applied force of a per-interval thrust at the equation instants of ``mode``."""
    f = interval_force(cmd, period, tau, delay)
    out: FloatArray = f[:-1] if mode == "speed" else 0.5 * (f[:-2] + f[1:-1])
    return out


def equation_data(plant: Plant, rec: Recording, filt: FilterSpec | None = None,
                  mode: str | None = None, closed_loop: bool = False,
                  speed: tuple[float, SpeedPrior] | None = None,
                  thrust_gap: int = 0) -> EquationData:
    """Build the residual of ``plant`` on ``rec`` (effects already in the plant included).

    ``closed_loop``: the thrust is a feedback of the measurements, so the mass and viscous
    instruments are built from the thrust one filter memory (``edge`` samples) earlier.
    ``speed``: the smoothed speed's noise and prior when ``rec`` is one part of the data
    (they are the whole data's, :func:`.parts.equation_data_parts`); default: ``rec``'s.
    ``thrust_gap`` > 0: the thrust reading is noisy (:func:`.reading.reading_gap`); no
    regressor uses the thrust nearer than that many samples to its instant.
    """
    fs = rec.sample_rate_hz  # the data's rate; the plant's own rate plays no part here
    mode = mode or ("position" if rec.speed_derived else "speed")
    if mode not in ("speed", "position"):
        raise DiagnoseError(f"unknown equation mode '{mode}'")
    spec = filt or choose_filter(rec.speed, fs)
    if len(rec) < max(MIN_SAMPLES, 4 * spec.edge):
        raise DiagnoseError(f"{len(rec)} samples are too few for the equation error "
                            f"(need {max(MIN_SAMPLES, 4 * spec.edge)} at {fs:g} Hz)")
    sos = butter_sos(spec.order, spec.cutoff_hz, fs)
    x, v, a, inertial = _nominal_dynamics(plant, rec, mode)
    tau = plant.thrust_lag.tau_s if plant.thrust_lag is not None else 0.0
    delay = plant.transport_delay.delay_s if plant.transport_delay is not None else 0.0
    T = 1.0 / fs
    cmd = np.asarray(rec.thrust, dtype=np.float64)
    force = _applied(cmd, T, tau, delay, mode)
    xs, vs, as_ = (sosfiltfilt(sos, s) for s in (x, v, a))
    v_lo, v_hi = _interval_ends(rec, mode, sos)
    if speed is None:
        noise = smoothed_speed_noise(rec, mode, sos)
        prior = SpeedPrior.from_speeds(np.concatenate([v_lo, v_hi]), noise, SIGN_SMOOTHING_MPS)
    else:
        noise, prior = speed
    resid = force - inertial - interval_effects(plant, xs, vs, v_lo, v_hi, force, T, mode,
                                                prior)
    t = rec.t[:-1] if mode == "speed" else rec.t[1:-1]
    y = np.ascontiguousarray(sosfiltfilt(sos, resid)[spec.edge:len(resid) - spec.edge:
                                                      spec.decimation])
    a_iv, v_iv, fiv, inst = reading_instruments(
        cmd, T, (plant.mass_kg, plant.viscous_n_per_mps), mode, a, v, thrust_gap,
        closed_loop, sos, (spec.edge, spec.decimation))
    return EquationData(x=xs, v=vs, v_lo=v_lo, v_hi=v_hi, a=as_, v_raw=v, a_raw=a,
                        a_iv=a_iv, v_iv=v_iv, cmd=cmd, force=force, y=y, t=t, period=T,
                        mode=mode, filt=spec, sos=sos, speed_noise_mps=noise,
                        sign_smoothing_mps=sign_width(noise), prior=prior,
                        force_iv=None if fiv is None else _applied(fiv, T, tau, delay, mode),
                        inst=inst, thrust_gap=thrust_gap, closed_loop=closed_loop)


def thinned_times(data: EquationData) -> FloatArray:
    """Time stamps of the regression samples (trimmed and decimated like ``y``)."""
    return thinned(data, data.t)


def thinned_sizes(data: EquationData) -> tuple[int, ...]:
    """Regression samples of each part (empty for one contiguous recording)."""
    if not data.parts:
        return ()
    e, d = data.filt.edge, data.filt.decimation
    return tuple(len(range(lo + e, hi - e, d)) for lo, hi in data.instants())


def thinned(data: EquationData, arr: FloatArray) -> FloatArray:
    """Trim and decimate a full-rate array without filtering (states for plots, bins)."""
    e, d = data.filt.edge, data.filt.decimation
    if not data.parts:
        out: FloatArray = np.asarray(arr)[e:len(arr) - e:d]
        return out
    a = np.asarray(arr)
    return np.concatenate([a[lo + e:hi - e:d] for lo, hi in data.instants()])
