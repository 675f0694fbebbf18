"""The library of interpretable effects, with the names diagnose reports.

Each effect is a force the nominal plant leaves out, written in the inverse-dynamics sign
``F = M a + B v + F_effects`` of :mod:`pmsm_sysid.core.physics.motor`, so a regressor's coefficient
is directly the effect's parameter:

=====================  ==========================================  ==========================
effect                 regressor(s) on the smoothed states          coefficient(s)
=====================  ==========================================  ==========================
force_offset           1                                            offset (N)
coulomb_friction       sign(v)                                      Fc (N)
stribeck_friction      exp(-(v/vs)²) sign(v), vs on a grid          static_n (N)
viscous_error          v                                            ΔB (N s/m)
mass_error             a                                            ΔM (kg)
spring                 x                                            k (N/m)
cogging                sin, cos(2π h x/p), pitch p on a grid        A_h cos φ_h, A_h sin φ_h
thrust_ripple          F sin, F cos(2π x/p), p on a grid            -r cos φ, -r sin φ
thrust_lag             (F(k) - F(k-1))/T  (detection)               τ (or a delay, same order)
=====================  ==========================================  ==========================

A thrust lag and a transport delay shorter than a sample both act, to first order, as
``τ dF/dt``; the detection regressor stands for both and :mod:`.estimate` tells them apart
(exactly, through :func:`.kinematics.interval_force`) as far as the data allow.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DiagnoseError
from .averaging import travel_gain
from .kinematics import PROJECTED, EquationData, projected, thinned
from .memo import content_key

FloatArray = NDArray[np.float64]

FIXED = ("force_offset", "coulomb_friction", "viscous_error", "mass_error", "spring",
         "thrust_lag")

OVERSAMPLE = 4  # grid points per independent wavenumber / Stribeck velocity
MAX_CYCLE_HZ_FACTOR = 1.0  # a position period must pass the filter at the median speed
CHUNK = 32  # columns filtered at a time (memory)
MAX_PITCHES = 400
MIN_PERIODS = 2.0  # periods over the travel for a position-periodic force to be told apart
#: Effects whose estimation columns are instruments (:func:`measured_columns`).
INSTRUMENTED = ("mass_error", "viscous_error", "thrust_lag", "thrust_ripple")
#: ... of which these are projected on the instruments after the parallel filter when
#: the thrust reading is noisy (:meth:`.kinematics.EquationData.instrument`).
FIRST_STAGE = ("mass_error", "viscous_error", "thrust_lag")


@dataclass(frozen=True)
class Effect:
    """One candidate: a library name plus its nonlinear parameter (pitch, vs, τ or delay)."""

    name: str
    pitch_m: float = 0.0
    velocity_mps: float = 0.0
    orders: tuple[int, ...] = (1,)
    tau_s: float = -1.0  # < 0: the linear detection regressor; >= 0: exact lag of tau_s
    delay_s: float = -1.0

    @property
    def dynamic(self) -> bool:
        """True when the effect is an exact lag/delay (no free linear coefficient)."""
        return self.tau_s >= 0.0 or self.delay_s >= 0.0

    @property
    def width(self) -> int:
        """Number of linear coefficients."""
        if self.dynamic:
            return 0
        if self.name in ("cogging",):
            return 2 * len(self.orders)
        return 2 if self.name == "thrust_ripple" else 1

    def label(self) -> str:
        if self.name == "cogging":
            return f"cogging(p={self.pitch_m * 1e3:.3f} mm, h={list(self.orders)})"
        if self.name == "thrust_ripple":
            return f"thrust_ripple(p={self.pitch_m * 1e3:.3f} mm)"
        if self.name == "stribeck_friction":
            return f"stribeck_friction(vs={self.velocity_mps * 1e3:.2f} mm/s)"
        if self.tau_s >= 0:
            return f"thrust_lag(tau={self.tau_s * 1e3:.3f} ms)"
        if self.delay_s >= 0:
            return f"transport_delay(d={self.delay_s * 1e3:.3f} ms)"
        return self.name


#: The travel gain and the sin and cos of the phase of one harmonic of one pitch, by
#: (pitch, harmonic): what a cogging column and a ripple column of that pitch both use.
Phases = dict[tuple[float, int], tuple[FloatArray, FloatArray, FloatArray]]


def _phase(data: EquationData, pitch_m: float, h: int,
           kept: Phases | None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Travel gain of harmonic ``h`` of ``pitch_m``, sin and cos of its phase ``h k x``
    (``kept``: the ones computed already for the same data, filled as they are made)."""
    got = None if kept is None else kept.get((pitch_m, h))
    if got is None:
        g = travel_gain(data.v, data.period, h / pitch_m, data.mode)
        arg = h * (2.0 * math.pi / pitch_m) * data.x  # one phase for both, the same bits
        got = (g, np.sin(arg), np.cos(arg))
        if kept is not None:
            kept[(pitch_m, h)] = got
    return got


def raw_columns(e: Effect, data: EquationData, kept: Phases | None = None) -> FloatArray:
    """Full-rate regressor columns of ``e`` (before parallel filtering), shape (N, width).

    ``kept``: the phases (:func:`_phase`) of ``data`` computed already: a ripple column of
    a pitch is made from the cogging column's gain, sin and cos (measured: they were all
    but a twentieth of a ripple column's cost, and the two families have the same pitches).
    """
    x, _v = data.x, data.v
    if e.name == "force_offset":
        return np.ones((len(x), 1))
    if e.name == "coulomb_friction":
        return data.friction()[:, None]
    if e.name == "stribeck_friction":
        return data.friction(e.velocity_mps)[:, None]
    if e.name == "viscous_error":  # instruments: at full rate, or in :meth:`columns`
        return (data.v_iv if data.inst is None else data.v_raw)[:, None]
    if e.name == "mass_error":
        return (data.a_iv if data.inst is None else data.a_raw)[:, None]
    if e.name == "spring":
        return x[:, None]
    if e.name == "cogging":
        out = np.empty((len(x), 2 * len(e.orders)))  # what column_stack of the pairs gives
        for i, h in enumerate(e.orders):
            g, sin, cos = _phase(data, e.pitch_m, h, kept)
            np.multiply(g, sin, out=out[:, 2 * i])
            np.multiply(g, cos, out=out[:, 2 * i + 1])
        return out
    if e.name == "thrust_ripple":
        g, sin, cos = _phase(data, e.pitch_m, 1, kept)
        g = g * data.regressor_force
        out = np.empty((len(x), 2))
        np.multiply(g, sin, out=out[:, 0])
        np.multiply(g, cos, out=out[:, 1])
        return out
    if e.name == "thrust_lag" and not e.dynamic:
        d = data.per_interval(lambda c: np.diff(c, prepend=c[0]), data.cmd) / data.period
        return data.pair(d)[:, None]
    raise DiagnoseError(f"effect '{e.name}' has no linear regressor")


def dynamic_part(e: Effect, data: EquationData) -> FloatArray:
    """Residual force of an exact lag/delay: nominal applied force minus the delayed one."""
    tau = max(e.tau_s, 0.0)
    delay = max(e.delay_s, 0.0)
    return data.instrument(data.project(data.force - data.forced(tau, delay)))


def columns(e: Effect, data: EquationData) -> FloatArray:
    """Parallel-filtered regressor columns of ``e`` (n × width): a family chunk of one
    (kept by its inputs, :func:`_projected_chunk`) where its inputs are listed."""
    inputs = inputs_key(e.name, data) if not e.dynamic else None
    if inputs is None:
        out = data.project(raw_columns(e, data))
    else:
        out = _projected_chunk((e,), data, inputs)
    return data.instrument(out) if e.name in FIRST_STAGE else out


def measured_columns(e: Effect, data: EquationData) -> FloatArray:
    """Filtered columns of ``e`` made of the signals as measured, under a noisy thrust
    reading: the force the corrected plant takes out of the equation error.

    Under a noisy reading the estimation columns (:func:`columns`, :func:`dynamic_part`)
    of the mass, viscous, lag and ripple terms are projections on instruments made of the
    thrust a gap away (:mod:`.instruments`): they give consistent coefficients, but such
    an instrument holds only part of the effect's force (a third to two thirds under 5 N of
    noise). The rest, ``(measured - instrumented) x coefficient``, belongs to the effect
    too: left in the residual, another effect would take it (a 1 ms lag's remainder was
    named Stribeck friction). With a clean reading (and under feedback) the instruments
    hold nearly all of it, and the measured acceleration holds the speed sensor's noise
    amplified by the mass: there the estimation columns are the effect's force.
    """
    if data.inst is None or not (e.dynamic or e.name in INSTRUMENTED):
        return dynamic_part(e, data) if e.dynamic else columns(e, data)
    if e.dynamic:
        tau, delay = max(e.tau_s, 0.0), max(e.delay_s, 0.0)
        return data.project(data.force - data.forced(tau, delay))
    if e.name == "mass_error":
        return data.project(data.a_raw[:, None])
    if e.name == "viscous_error":
        return data.project(data.v_raw[:, None])
    if e.name == "thrust_lag":
        d = data.per_interval(lambda c: np.diff(c, prepend=c[0]), data.cmd) / data.period
        return data.project(data.pair(d)[:, None])
    if e.name == "thrust_ripple":
        k = 2.0 * math.pi / e.pitch_m
        g = travel_gain(data.v, data.period, 1.0 / e.pitch_m, data.mode) * data.force
        return data.project(np.column_stack([g * np.sin(k * data.x), g * np.cos(k * data.x)]))
    return columns(e, data)


@dataclass(frozen=True)
class Family:
    """The candidates of one effect name, with the number of independent tests it holds."""

    name: str
    members: tuple[Effect, ...]
    n_independent: float


def periods_seen(e: Effect, data: EquationData) -> float:
    """How many periods of a cogging or ripple pitch the travel covers (inf otherwise).

    With fewer than ``MIN_PERIODS`` no phase of the force is met twice: one period of a
    sine (with harmonics) over the stroke is just a smooth curve over position -- a local
    bump fits it as well -- so the data cannot say the force is periodic.
    """
    if e.name not in ("cogging", "thrust_ripple") or e.pitch_m <= 0:
        return math.inf
    return float(np.ptp(thinned(data, data.x))) / e.pitch_m


def pitch_grid(data: EquationData) -> tuple[FloatArray, float]:
    """Candidate pitches (m) and the number of independent ones.

    Wavenumbers 1/p from 1/R (one period over the travel R) to fc/median|v| (a period is
    crossed slower than the filter's cut-off at the median speed), spaced 1/(4R): four-fold
    oversampling of the independent Fourier wavenumbers 1/R. Long travels would need more
    than ``MAX_PITCHES`` points: the spacing is then relaxed to 1/(2R) and, if still too
    many, the shortest pitches are left out (the searched range is reported).
    """
    xs = thinned(data, data.x)
    travel = float(np.ptp(xs))
    vmed = float(np.median(np.abs(thinned(data, data.v))))
    if travel <= 0 or vmed <= 0:
        return np.zeros(0), 0.0
    k_lo = 1.0 / travel
    k_hi = MAX_CYCLE_HZ_FACTOR * data.filt.cutoff_hz / vmed
    over = OVERSAMPLE
    if (k_hi - k_lo) * travel * over > MAX_PITCHES:
        over = 2
        k_hi = min(k_hi, k_lo + MAX_PITCHES / (over * travel))
    if k_hi <= k_lo:
        return np.zeros(0), 0.0
    ks = np.arange(k_lo, k_hi, 1.0 / (over * travel))
    pitches = np.asarray(1.0 / ks, dtype=np.float64)
    return pitches, (k_hi - k_lo) * travel


def stribeck_grid(data: EquationData) -> tuple[FloatArray, float]:
    """Stribeck velocities, log-spaced from 3 smoothing widths to half the speed range."""
    vmax = float(np.quantile(np.abs(thinned(data, data.v)), 0.95))
    lo, hi = 3e-3, 0.5 * vmax
    if hi <= lo:
        return np.zeros(0), 0.0
    n = max(2, math.ceil(OVERSAMPLE * math.log2(hi / lo)))
    return np.geomspace(lo, hi, n), n / OVERSAMPLE


def families(data: EquationData, exclude: tuple[str, ...] = ()) -> list[Family]:
    """All candidate families on ``data`` (minus ``exclude``)."""
    out = [Family(n, (Effect(n),), 1.0) for n in FIXED if n not in exclude]
    pitches, n_p = pitch_grid(data)
    if len(pitches):
        for name in ("cogging", "thrust_ripple"):
            if name not in exclude:
                out.append(Family(name, tuple(Effect(name, pitch_m=float(p)) for p in pitches),
                                  max(n_p, 1.0)))
    vs, n_v = stribeck_grid(data)
    if len(vs) and "stribeck_friction" not in exclude:
        out.append(Family("stribeck_friction",
                          tuple(Effect("stribeck_friction", velocity_mps=float(s)) for s in vs),
                          max(n_v, 1.0)))
    return out


def _raw_inputs(name: str, data: EquationData) -> tuple[Any, ...] | None:
    """What :func:`raw_columns` reads of ``data`` for effects ``name`` (arrays, numbers),
    or None if not listed here (test_plantfit_speed changes each field of the data in
    turn: whenever the columns change, so do these)."""
    if name in ("coulomb_friction", "stribeck_friction"):
        prior = None if data.prior is None else data.prior.digest()
        return data.v_lo, data.v_hi, data.sign_smoothing_mps, prior
    if name == "viscous_error":
        return (data.v_iv if data.inst is None else data.v_raw,)
    if name == "mass_error":
        return (data.a_iv if data.inst is None else data.a_raw,)
    if name in ("force_offset", "spring"):
        return (data.x,)
    if name == "cogging":
        return data.x, data.v, data.period, data.mode
    if name == "thrust_ripple":
        return data.x, data.v, data.period, data.mode, data.regressor_force
    if name == "thrust_lag":
        return data.cmd, data.period, data.mode, data.parts
    return None


def inputs_key(name: str, data: EquationData) -> bytes | None:
    """Content key of everything a chunk of family ``name``'s filtered columns is made
    of, before the members: its raw inputs and the filter (None: not keyed)."""
    inputs = _raw_inputs(name, data)
    if inputs is None:
        return None
    bounds = tuple(data.instants()) if data.parts else ()
    return content_key("family inputs", name, *inputs, data.sos, data.filt.edge,
                       data.filt.decimation, bounds)


def _projected_chunk(chunk: tuple[Effect, ...], data: EquationData,
                     inputs: bytes | None, kept: Phases | None = None) -> FloatArray:
    """The members' raw columns filtered (:meth:`.kinematics.EquationData.project`), kept
    by the inputs' key and the members: measured, building and hashing the raw columns
    was most of a scan whose filtered columns were already kept (``kept``: as in
    :func:`raw_columns`)."""
    def compute() -> FloatArray:
        raw = np.concatenate([raw_columns(e, data, kept) for e in chunk], axis=1)
        if inputs is None:
            return data.project(raw)
        bounds = tuple(data.instants()) if data.parts else ()
        return projected(data.sos, raw, data.filt.edge, data.filt.decimation, bounds)

    if inputs is None:
        return compute()
    return PROJECTED.array(content_key("family chunk", inputs, chunk), compute)


def project_made(data: EquationData, what: bytes, make: Callable[[], FloatArray],
                 ) -> FloatArray:
    """:meth:`.kinematics.EquationData.project` of the columns ``make()`` builds, kept by
    ``what`` (a content key of everything ``make`` reads of ``data``) instead of by their
    own bytes: when kept, they are neither built nor hashed again (measured: hashing the
    columns built only to look them up was a tenth of a diagnosis)."""
    e, d = data.filt.edge, data.filt.decimation
    bounds = tuple(data.instants()) if data.parts else ()
    key = content_key("project made", what, data.sos, e, d, bounds)
    return PROJECTED.array(key, lambda: projected(
        data.sos, np.asarray(make(), dtype=np.float64), e, d, bounds))


def family_chunks(fam: Family, data: EquationData,
                  kept: Phases | None = None) -> Iterator[tuple[int, FloatArray]]:
    """Filtered columns of the members, ``CHUNK`` columns at a time: (first member index,
    array of shape (members in chunk, n, width)); ``kept`` as in :func:`raw_columns`."""
    width = fam.members[0].width
    inputs = inputs_key(fam.name, data)
    for start, chunk in _chunks(fam.members, max(1, CHUNK // width)):
        proj = _projected_chunk(chunk, data, inputs, kept)
        if fam.name in FIRST_STAGE:
            proj = data.instrument(proj)
        yield start, proj.reshape(data.n, len(chunk), width).transpose(1, 0, 2)


def family_columns(fam: Family, data: EquationData) -> FloatArray:
    """Filtered columns of every member, shape (members, n, width)."""
    out = np.empty((len(fam.members), data.n, fam.members[0].width))
    for start, cols in family_chunks(fam, data):
        out[start:start + len(cols)] = cols
    return out


def _chunks(seq: tuple[Effect, ...], size: int) -> Iterator[tuple[int, tuple[Effect, ...]]]:
    for i in range(0, len(seq), size):
        yield i, seq[i:i + size]
