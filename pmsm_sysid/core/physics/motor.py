"""The linear PMSM axis as a sampled simulator (timing: the thrust stamped t_k is held over [t_k,
t_k+1)).

Mechanical equation, integrated with fixed-step RK4::

    M dv/dt = F_motor + w - B v - F_effects(x, v, F)      dx/dt = v
    F_motor = F * (1 + ripple(x))                          (ripple is inside F_effects)
    tau dF/dt = F_cmd(t - delay) - F                       (thrust lag; F = F_cmd without it)

``F_cmd`` is the thrust command held over each sample period (zero-order hold) and ``w`` the
white process force of the ``noise`` block, drawn once per sample and held. Numerical choices:

* The lag state is integrated in closed form inside each sub-step (the command is constant
  there): F(t) = F_cmd + d exp(-t/tau). The damped mass's linear response phi(t) to that
  transient is taken in closed form too (RK4 carries v - phi), so a lag of any length, such
  as the winding constant L/R = 0.41 ms, neither destabilises RK4 nor needs smaller steps.
* ``plant.substeps`` is the minimum number of RK4 steps per sample (default 8: h = 0.25 ms
  at 500 Hz, 0.6 L/R). The simulator raises it when an effect is stiff, so that h*lambda <= 1
  for the fastest mode (viscous B/M, smoothed friction Fc/(M v_s), spring/cogging
  sqrt(k/M)).
* Near v = 0 a step is split (up to 64 pieces) so that each piece changes v by at most one
  smoothing scale of sign(v) and h * (friction slope / M) <= 0.2: velocity reversals and
  rests are resolved.
* sign(v) is ``tanh(v / smoothing_mps)`` (default 1 mm/s): smooth, so RK4 keeps its order;
  a body left to rest under a force below the friction level creeps at about
  ``smoothing_mps * atanh(F/Fc)`` instead of sticking.
* A transport delay of any length is exact: the delayed command switches value at
  ``t_k + delay`` and the sample period is split there into two RK4-integrated pieces.
"""

from __future__ import annotations

import json
import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import DataError, PlantError
from ..recording.signals import Recording
from .integrator import Rk4, effect_function
from .plant import Plant, plant_to_dict

FloatArray = NDArray[np.float64]

MAX_SUBSTEPS = 4096
_HISTORY_MIN = 1024
#: most normals a noise stream draws at once (:class:`Normals`)
NOISE_BLOCK = 4096


def _effects(plant: Plant, x: Any, v: Any, f: Any,
             sin: Callable[[Any], Any], exp: Callable[[Any], Any],
             tanh: Callable[[Any], Any]) -> Any:
    """F_effects for scalars (math) or arrays (numpy): one formula for both paths."""
    total: Any = 0.0
    cog = plant.cogging
    if cog is not None:
        k = 2.0 * math.pi / cog.pitch_m
        total = total + cog.amplitude_n * sin(k * x + cog.phase_rad)
        for h in cog.harmonics:
            total = total + h.amplitude_n * sin(h.order * k * x + h.phase_rad)
    cf = plant.coulomb_friction
    if cf is not None:
        total = total + cf.amplitude_n * tanh(v / cf.smoothing_mps)
    sf = plant.stribeck_friction
    if sf is not None:
        hump = exp(-((v / sf.velocity_mps) ** 2))
        total = total + sf.static_n * hump * tanh(v / sf.smoothing_mps)
    if plant.force_offset is not None:
        total = total + plant.force_offset.amplitude_n
    rip = plant.thrust_ripple
    if rip is not None:
        total = total - rip.relative * sin(2.0 * math.pi * x / rip.pitch_m + rip.phase_rad) * f
    if plant.spring is not None:
        total = total + plant.spring.stiffness_n_per_m * x
    return total


def effects_force(plant: Plant, x: ArrayLike, v: ArrayLike, f_applied: ArrayLike) -> FloatArray:
    """Vectorised F_effects(x, v, F) in ``M dv/dt = F - B v - F_effects`` (N).

    Cogging ``A sin(2 pi x/p + phi) + harmonics``, Coulomb ``Fc sign(v)``, Stribeck, the
    offset, minus the ripple ``r sin(2 pi x/p + phi) F``, and the spring ``k x``. Thrust lag
    and transport delay are dynamic and live in :class:`MotorSimulator`.
    """
    xa, va, fa = (np.asarray(a, dtype=np.float64) for a in (x, v, f_applied))
    out = _effects(plant, xa, va, fa, np.sin, np.exp, np.tanh)
    return np.asarray(np.broadcast_to(out, np.broadcast_shapes(xa.shape, va.shape, fa.shape)),
                      dtype=np.float64).copy()


def friction_rate(plant: Plant) -> float:
    """Largest rate (1/s) of the smoothed friction near v = 0: d(F_friction)/dv / M."""
    slope = 0.0
    if plant.coulomb_friction is not None:
        cf = plant.coulomb_friction
        slope += abs(cf.amplitude_n) / cf.smoothing_mps
    if plant.stribeck_friction is not None:
        sf = plant.stribeck_friction
        slope += sf.static_n / min(sf.smoothing_mps, sf.velocity_mps)
    return slope / plant.mass_kg


def stiff_rate(plant: Plant) -> float:
    """Fastest mechanical rate (1/s) that bounds the RK4 step: damping plus friction
    slope, or the stiffness of springs and cogging."""
    m = plant.mass_kg
    stiffness = plant.spring.stiffness_n_per_m if plant.spring is not None else 0.0
    if plant.cogging is not None:
        cog = plant.cogging
        grad = abs(cog.amplitude_n) + sum(h.order * abs(h.amplitude_n) for h in cog.harmonics)
        stiffness += 2.0 * math.pi * grad / cog.pitch_m
    return max(plant.viscous_n_per_mps / m + friction_rate(plant), math.sqrt(stiffness / m))


def effective_substeps(plant: Plant) -> int:
    """RK4 steps per sample actually used: ``plant.substeps`` raised for stiff effects."""
    period = plant.sample_period_s
    return int(max(plant.substeps, math.ceil(period * stiff_rate(plant) - 1e-12)))


@dataclass(frozen=True)
class MotorState:
    """True (noise-free) state: position (m), speed (m/s), lagged motor force (N)."""

    position_m: float
    speed_mps: float
    force_n: float


class MotorSimulator:
    """Sample-by-sample simulator: ``measure()`` at t_k, then ``advance(thrust_k)``.

    The same calls in the same order give bit-for-bit the same numbers, whether they come from
    :func:`simulate` or from the live sim node. All randomness comes from ``seed``: one
    stream for the measurement noise (two normals per sample) and one for the process force
    (one normal per sample), drawn whether or not the plant has a ``noise`` block, so that
    switching noise on at run time does not shift the other streams.
    """

    def __init__(self, plant: Plant, seed: int = 0, x0: float = 0.0, v0: float = 0.0) -> None:
        if not (math.isfinite(x0) and math.isfinite(v0)):
            raise PlantError(f"initial state must be finite, got x0={x0}, v0={v0}")
        meas_seq, force_seq, thrust_seq = np.random.SeedSequence(int(seed)).spawn(3)
        self._meas_noise, self._force_noise, self._thrust_noise = (
            Normals(np.random.Generator(np.random.PCG64(s)))
            for s in (meas_seq, force_seq, thrust_seq))
        self._zt = 0.0
        self._x, self._v, self._f = float(x0), float(v0), 0.0
        self._k = 0
        self._history: deque[float] = deque(maxlen=_HISTORY_MIN)
        self._plant = plant
        self._configure(plant)
        self._z = self._draw_measurement()

    # ------------------------------------------------------------------ public interface
    @property
    def plant(self) -> Plant:
        return self._plant

    @property
    def sample_index(self) -> int:
        """Number of samples advanced so far (k of the next ``measure``)."""
        return self._k

    @property
    def time_s(self) -> float:
        """Time of the current sample, k / fs (s)."""
        return self._k / self._plant.sample_rate_hz

    @property
    def state(self) -> MotorState:
        return MotorState(self._x, self._v, self._f)

    @property
    def substeps(self) -> int:
        """RK4 steps per sample in use (see :func:`effective_substeps`)."""
        return self._n_sub

    def measure(self) -> tuple[float, float]:
        """(speed, position) measured at the current sample: noise then quantisation."""
        speed, position = self._v, self._x
        noise, quant = self._plant.noise, self._plant.quantisation
        if noise is not None:
            speed += noise.speed_std * self._z[0]
            position += noise.position_std * self._z[1]
        if quant is not None:
            speed = _quantise(speed, quant.speed_mps)
            position = _quantise(position, quant.position_m)
        return speed, position

    def measured_thrust(self, thrust: float) -> float:
        """The thrust a sensor records for the command ``thrust`` applied at this sample
        (the command itself unless the noise block has ``thrust_std``)."""
        noise = self._plant.noise
        if noise is None or noise.thrust_std == 0.0:
            return float(thrust)
        return float(thrust) + noise.thrust_std * self._zt

    def advance(self, thrust: float) -> None:
        """Hold ``thrust`` (N) for one sample period and step the state to t_{k+1}."""
        u = float(thrust)
        if not math.isfinite(u):
            raise DataError(f"thrust at sample {self._k} is not finite ({thrust})")
        self._x, self._v, self._f = self._step(self._x, self._v, self._f, u)
        self._k += 1
        self._z = self._draw_measurement()

    def _step(self, x: float, v: float, f: float, u: float) -> tuple[float, float, float]:
        """The state (x, v, F) one sample period on from (``x``, ``v``, ``f``): ``u`` joins
        the command history, whose delayed values are held over the period with this
        sample's process force."""
        history = self._history
        history.append(u)
        w = self._w_std * self._force_noise.draw()
        m, r, run = self._delay_m, self._delay_r, self._rk4.run
        if r == 0.0:
            return run(x, v, f, self._period, history[-1 - m] if m < len(history) else 0.0, w)
        x, v, f = run(x, v, f, r, history[-2 - m] if m + 1 < len(history) else 0.0, w)
        return run(x, v, f, self._period - r, history[-1 - m] if m < len(history) else 0.0, w)

    def replay(self, thrust: list[float], restart: list[int], position: list[float],
               speed: list[float]) -> tuple[list[float], list[float]]:
        """(speeds, positions) at each sample while ``thrust`` is advanced sample by sample,
        the state set to (``position[k]``, ``speed[k]``) (lag settled) before every sample
        ``k`` in ``restart``; stops after the first non-finite speed (the lists are shorter).

        The same states as ``set_state``/``state``/``advance`` per sample, for a plant without
        a noise block only (its measurement draws are skipped: nothing measures). One loop
        with the state in locals (with Rk4's unlagged paths, diagnose of a simulated 10 s
        recording 0.18 s -> 0.14 s of CPU)."""
        if self._plant.noise is not None:
            raise PlantError("replay needs a plant without a noise block")
        step = self._step
        x, v, f = self._x, self._v, self._f
        restarts, out_v, out_x = set(restart), [], []
        isfinite = math.isfinite
        for k, u in enumerate(thrust):
            if k in restarts:
                self.set_state(position[k], speed[k])
                x, v, f = self._x, self._v, self._f
            out_v.append(v)
            out_x.append(x)
            if not isfinite(v):
                break
            if not isfinite(u):
                raise DataError(f"thrust at sample {self._k + k} is not finite ({u})")
            x, v, f = step(x, v, f, u)
        self._x, self._v, self._f = x, v, f
        self._k += len(out_v) if isfinite(v) else len(out_v) - 1
        return out_v, out_x

    def set_state(self, position_m: float, speed_mps: float, force_n: float | None = None) -> None:
        """Overwrite the true state now (e.g. to start from a measured state); ``force_n`` is
        the lag state (default: the newest command, i.e. a settled lag)."""
        force = force_n if force_n is not None else self._command(0)
        if not all(math.isfinite(a) for a in (position_m, speed_mps, force)):
            raise PlantError("state must be finite")
        self._x, self._v, self._f = float(position_m), float(speed_mps), float(force)

    def set_plant(self, plant: Plant) -> None:
        """Change parameters now, keeping x, v, the lag state, the delay line and the noise."""
        if plant.sample_rate_hz != self._plant.sample_rate_hz:
            raise PlantError("the sample rate cannot change during a run "
                             f"({self._plant.sample_rate_hz} -> {plant.sample_rate_hz} Hz)")
        self._plant = plant
        self._configure(plant)

    # ------------------------------------------------------------------ internals
    def _configure(self, plant: Plant) -> None:
        period = plant.sample_period_s
        self._n_sub = effective_substeps(plant)
        if self._n_sub > MAX_SUBSTEPS:
            raise PlantError(f"plant too stiff to simulate at {plant.sample_rate_hz:g} Hz: it "
                             f"needs {self._n_sub} RK4 steps per sample (limit {MAX_SUBSTEPS});"
                             " raise smoothing_mps or lower the friction/stiffness")
        self._h = period / self._n_sub
        delay = plant.transport_delay.delay_s if plant.transport_delay is not None else 0.0
        ratio = delay / period
        m = math.floor(ratio + 1e-9)
        frac = (ratio - m) * period
        self._delay_m = m
        self._delay_r = 0.0 if frac <= 1e-9 * period else frac
        if m + 2 > (self._history.maxlen or 0):
            self._history = deque(self._history, maxlen=m + 2)
        scales = [blk.smoothing_mps for blk in (plant.coulomb_friction, plant.stribeck_friction)
                  if blk is not None]
        self._rk4 = Rk4(plant, self._h, effect_function(plant), min(scales) if scales else 0.0,
                        friction_rate(plant))
        self._period = period
        self._w_std = plant.noise.force_std if plant.noise is not None else 0.0

    def _draw_measurement(self) -> tuple[float, float]:
        self._zt = self._thrust_noise.draw()
        meas = self._meas_noise
        return meas.draw(), meas.draw()

    def _command(self, back: int) -> float:
        """The command ``back`` samples before the newest (0 before the start)."""
        return self._history[-1 - back] if back < len(self._history) else 0.0


class Normals:
    """Standard normals of one generator, one per :meth:`draw`: the numbers and the order
    of ``float(rng.standard_normal())`` per draw, taken from blocks the generator fills
    value by value (a block of n is the next n single draws), far cheaper per value.
    Blocks grow from 16 to :data:`NOISE_BLOCK` values, so a short simulation draws few."""

    __slots__ = ("_buf", "_i", "_rng", "_size")

    def __init__(self, rng: np.random.Generator) -> None:
        self._rng = rng
        self._buf: list[float] = []
        self._i = 0
        self._size = 16

    def draw(self) -> float:
        i = self._i
        if i == len(self._buf):
            size = min(self._size, NOISE_BLOCK)
            self._buf, i = self._rng.standard_normal(size).tolist(), 0
            self._size = 2 * size
        self._i = i + 1
        return self._buf[i]


def _quantise(value: float, step: float) -> float:
    return round(value / step) * step if step > 0 else value


def _checked(thrust: ArrayLike, k0: int = 0) -> FloatArray:
    u = np.asarray(thrust, dtype=np.float64)
    if u.ndim != 1 or len(u) < 1:
        raise DataError(f"thrust must be a 1-D array with samples, got shape {u.shape}")
    if not np.isfinite(u).all():
        first = k0 + int(np.argmax(~np.isfinite(u)))
        raise DataError(f"thrust has non-finite samples (first at index {first})")
    return u


def _run(sim: MotorSimulator, plant: Plant, u: FloatArray, seed: int, k0: int,
         t0: float) -> Recording:
    """Samples ``k0 ..`` of a simulation: measure, record the thrust, advance; per sample."""
    n = len(u)
    measured = []
    recorded = []
    measure, thrust_reading, advance = sim.measure, sim.measured_thrust, sim.advance
    for uk in u.tolist():  # Python floats: the same values, cheaper per sample than numpy's
        measured.append(measure())
        recorded.append(thrust_reading(uk))
        advance(uk)
    fs = plant.sample_rate_hz
    meta = {"plant": json.dumps(plant_to_dict(plant), sort_keys=True), "seed": str(seed),
            "simulator": "pmsm_sysid.core.physics.motor"}
    speed, position = np.array(measured, dtype=np.float64).reshape(n, 2).T
    return Recording(t=t0 + (k0 + np.arange(n)) / fs, thrust=np.array(recorded, dtype=np.float64),
                     speed=speed.copy(), position=position.copy(), sample_rate_hz=fs,
                     source="simulate", meta=meta)


def simulate(plant: Plant, thrust: ArrayLike, seed: int = 0, x0: float = 0.0, v0: float = 0.0,
             t0: float = 0.0) -> Recording:
    """Run ``thrust`` (one value per sample) through the plant (zero-order hold).

    ``speed[k], position[k]`` are measured at ``t[k] = t0 + k/fs``, then ``thrust[k]`` is
    held over [t_k, t_{k+1}), so y(k) depends on u(k-1) and earlier.
    """
    u = _checked(thrust)
    return _run(MotorSimulator(plant, seed=seed, x0=x0, v0=v0), plant, u, seed, 0, t0)


#: Samples per block of :func:`simulate_blocks` (8 MB of arrays).
BLOCK = 1 << 16


def simulate_blocks(plant: Plant, thrust: Callable[[int, int], ArrayLike], n: int,
                    seed: int = 0, block: int = BLOCK) -> Iterator[Recording]:
    """:func:`simulate` of ``n`` samples, ``block`` at a time: the same numbers, with the
    memory of one block. ``thrust(k0, m)`` gives samples ``k0 .. k0+m-1`` of the input."""
    sim = MotorSimulator(plant, seed=seed)
    for k0 in range(0, n, block):
        u = _checked(thrust(k0, min(block, n - k0)), k0)
        yield _run(sim, plant, u, seed, k0, 0.0)
