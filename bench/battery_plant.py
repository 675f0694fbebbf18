"""An independent simulator of a linear drive for the diagnose battery.

It shares nothing with ``pmsm_sysid.core.physics.motor`` but the parameter values of the nominal
motor: its own RK4 integration (10 steps per sample, lag as a state), its own friction
regularisation (``v / sqrt(v² + eps²)``), its own noise streams, and effects the library does
not have (a localized force bump, friction over part of the stroke, an actuator dead zone, a
slow time-periodic disturbance). A case is driven open loop (excitation plus a slow 0.5 Hz
positioning move) or by a PID position loop with the excitation injected into its output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.recording.signals import Recording

FloatArray = NDArray[np.float64]

FS = 500.0
N = 2500
M0, B0 = 2.3213, 32.4992
EPS = 5e-4  # friction regularisation (m/s)
SUB = 10
NOISE = {"low": (0.001, 2e-6, 0.3), "high": (0.005, 1e-5, 1.5)}  # speed, position, force


@dataclass(frozen=True)
class Truth:
    """The real plant: nominal mass/damper plus any of the listed forces."""

    mass: float = M0
    viscous: float = B0
    coulomb: float = 0.0
    stribeck: float = 0.0
    stribeck_v: float = 0.01
    offset: float = 0.0
    spring: float = 0.0
    cogging: tuple[float, float, float] = (0.0, 0.007, 0.0)  # amplitude, pitch, phase
    ripple: tuple[float, float, float] = (0.0, 0.024, 0.0)  # relative, pitch, phase
    lag_s: float = 0.0
    bump: tuple[float, float, float] = (0.0, 0.0, 0.003)  # amplitude, centre, sigma
    zone: tuple[float, float, float] = (0.0, 0.0, 0.0)  # friction, start, stop
    dead_zone: float = 0.0
    periodic: tuple[float, float] = (0.0, 0.25)  # amplitude, frequency
    process: float | None = None  # process force std overriding the noise level's
    thrust_noise: float = 0.0  # thrust sensor noise std (N): recorded, not applied


@dataclass(frozen=True)
class Case:
    """One battery entry: truth, drive, excitation, noise level and seed."""

    kind: str
    truth: Truth
    loop: str  # "open" | "closed"
    excitation: str
    noise: str
    seed: int
    expect: dict[str, dict[str, float]] = field(default_factory=dict)
    axis: str = ""  # out-of-library: the axis the unexplained force lives on
    region: tuple[float, float] = (0.0, 0.0)

    @property
    def label(self) -> str:
        return f"{self.kind}/{self.loop}/{self.excitation}/{self.noise}/s{self.seed}"


def _sgn(v: float) -> float:
    return v / math.sqrt(v * v + EPS * EPS)


def _force(tr: Truth, x: float, v: float, f: float, t: float) -> float:
    """Net force on the mover apart from the process noise (applied thrust f)."""
    s = _sgn(v)
    out = f * (1.0 + tr.ripple[0] * math.sin(2 * math.pi * x / tr.ripple[1] + tr.ripple[2]))
    out -= tr.viscous * v + tr.coulomb * s + tr.offset + tr.spring * x
    if tr.stribeck:
        out -= tr.stribeck * math.exp(-(v / tr.stribeck_v) ** 2) * s
    if tr.cogging[0]:
        out -= tr.cogging[0] * math.sin(2 * math.pi * x / tr.cogging[1] + tr.cogging[2])
    if tr.bump[0]:
        out -= tr.bump[0] * math.exp(-0.5 * ((x - tr.bump[1]) / tr.bump[2]) ** 2)
    if tr.zone[0]:
        w = 5e-4
        inside = 0.5 * (math.tanh((x - tr.zone[1]) / w) - math.tanh((x - tr.zone[2]) / w))
        out -= tr.zone[0] * inside * s
    if tr.periodic[0]:
        out -= tr.periodic[0] * math.sin(2 * math.pi * tr.periodic[1] * t)
    return out


def _actuator(tr: Truth, u: float) -> float:
    d = tr.dead_zone
    if d <= 0:
        return u
    return math.copysign(max(abs(u) - d, 0.0), u)


class Drive:
    """State (x, v, lagged force), stepped one sample with the command held."""

    def __init__(self, truth: Truth, rng: np.random.Generator, process_std: float,
                 fs: float = FS) -> None:
        self.tr, self.rng, self.w_std, self.fs = truth, rng, process_std, fs
        self.x = self.v = self.f = 0.0
        self.t = 0.0

    def _deriv(self, x: float, v: float, f: float, u: float, w: float,
               t: float) -> tuple[float, float, float]:
        tau = self.tr.lag_s
        df = (u - f) / tau if tau > 0 else 0.0
        force = f if tau > 0 else u
        return v, (_force(self.tr, x, v, force, t) + w) / self.tr.mass, df

    def step(self, cmd: float) -> None:
        u = _actuator(self.tr, cmd)
        w = self.w_std * float(self.rng.standard_normal())
        h = 1.0 / (self.fs * SUB)
        x, v, f, t = self.x, self.v, self.f, self.t
        for _ in range(SUB):
            k1 = self._deriv(x, v, f, u, w, t)
            k2 = self._deriv(x + h / 2 * k1[0], v + h / 2 * k1[1], f + h / 2 * k1[2], u, w,
                             t + h / 2)
            k3 = self._deriv(x + h / 2 * k2[0], v + h / 2 * k2[1], f + h / 2 * k2[2], u, w,
                             t + h / 2)
            k4 = self._deriv(x + h * k3[0], v + h * k3[1], f + h * k3[2], u, w, t + h)
            x += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            f += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
            t += h
        self.x, self.v, self.f, self.t = x, v, f, t


def _excitation(kind: str, seed: int, amplitude: float | None = None, n: int = N,
                fs: float = FS) -> FloatArray:
    return make_excitation(kind, n, fs, seed=1000 + seed, amplitude_n=amplitude)


def record(case: Case, seed: int, fs: float = FS, n: int = N) -> Recording:
    """Simulate ``case`` with noise/excitation ``seed`` (the held-out run uses another), at
    ``fs`` for ``n`` samples."""
    sv, sx, sw = NOISE[case.noise]
    sw = case.truth.process if case.truth.process is not None else sw
    rng = np.random.default_rng(seed)
    drive = Drive(case.truth, rng, sw, fs)
    t = np.arange(n) / fs
    thrust, speed, position = np.empty(n), np.empty(n), np.empty(n)
    if case.loop == "open":
        exc = _excitation(case.excitation, seed, None, n, fs) + 3.0 * np.cos(
            2 * math.pi * 0.5 * t)
    else:
        exc = _excitation(case.excitation, seed, 6.0, n, fs)
        ref = 0.02 * np.sin(2 * math.pi * 0.4 * t) + 0.004 * np.sin(2 * math.pi * 1.7 * t + 0.7)
        ref *= np.where(t < 0.5, 0.5 * (1 - np.cos(np.pi * t / 0.5)), 1.0)
        vref = np.gradient(ref) * fs
        w = 2 * math.pi * 15.0
        kp, kd, ki = M0 * w * w, 2 * 0.7 * w * M0 - B0, 0.1 * M0 * w ** 3
    integral = 0.0
    for k in range(n):
        speed[k] = drive.v + sv * rng.standard_normal()
        position[k] = round((drive.x + sx * rng.standard_normal()) / 1e-6) * 1e-6
        if case.loop == "open":
            cmd = exc[k]
        else:
            err = ref[k] - position[k]
            integral += err / fs
            cmd = kp * err + kd * (vref[k] - speed[k]) + ki * integral + exc[k]
        thrust[k] = cmd + case.truth.thrust_noise * rng.standard_normal() \
            if case.truth.thrust_noise else cmd
        drive.step(cmd)
    return Recording(t=t, thrust=thrust, speed=speed, position=position, sample_rate_hz=fs,
                     source="battery simulator", meta={"case": case.label})
