"""The simulator's inner loop: RK4 over one piece of a sample period, for one plant.

:class:`Rk4` is the integration :mod:`pmsm_sysid.core.physics.motor` describes (the lag force
``F(t) = cmd + d exp(-t/tau)`` exact, RK4 on ``v - phi``, steps split near ``v = 0``), written
for speed: one function with local variables, the plant's constants and the exponentials of
each step size computed once, and :func:`effect_function`, the scalar ``F_effects`` with each
block's constants taken out of the plant once. Every result is computed with the same floating
point operations in the same order as the formula of ``motor._effects`` and a step of
classic RK4 written out call by call, so the numbers are the same bit for bit
(``test/test_physics_speed.py`` compares them).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from .plant import Plant

#: F_effects(x, v, F) of one plant, for floats
EffectForce = Callable[[float, float, float], float]

_MAX_FINE_STEPS = 64
_NEAR_ZERO_HLAMBDA = 0.2
_TWO_PI = 2.0 * math.pi


def effect_function(plant: Plant) -> EffectForce | None:
    """The plant's ``F_effects(x, v, F)`` for floats (None: the plant has no effect force).

    The same terms in the same order as ``motor._effects`` (cogging and its harmonics,
    Coulomb, Stribeck, offset, minus ripple, spring), each with its constants read once; a
    plant with one block gets that block's term alone.
    """
    cog, cf, sf = plant.cogging, plant.coulomb_friction, plant.stribeck_friction
    off, rip, spring = plant.force_offset, plant.thrust_ripple, plant.spring
    if all(b is None for b in (cog, cf, sf, off, rip, spring)):
        return None
    sin, tanh, exp = math.sin, math.tanh, math.exp
    k = 2.0 * math.pi / cog.pitch_m if cog is not None else 0.0
    ca, cp = (cog.amplitude_n, cog.phase_rad) if cog is not None else (0.0, 0.0)
    harmonics = tuple((h.order * k, h.amplitude_n, h.phase_rad)
                      for h in (cog.harmonics if cog is not None else ()))
    fc, fs = (cf.amplitude_n, cf.smoothing_mps) if cf is not None else (0.0, 1.0)
    ss, sv, sw = ((sf.static_n, sf.velocity_mps, sf.smoothing_mps) if sf is not None
                  else (0.0, 1.0, 1.0))
    offset = off.amplitude_n if off is not None else 0.0
    rr, rp, rph = (rip.relative, rip.pitch_m, rip.phase_rad) if rip is not None else (0.0, 1.0,
                                                                                      0.0)
    stiffness = spring.stiffness_n_per_m if spring is not None else 0.0
    has = (cog is not None, cf is not None, sf is not None, off is not None, rip is not None,
           spring is not None)
    has_cog, has_cf, has_sf, has_off, has_rip, has_spring = has
    if sum(has) == 1 and not harmonics:  # one block: its term alone, no look at the others
        if has_cog:
            return lambda x, v, f: 0.0 + ca * sin(k * x + cp)
        if has_cf:
            return lambda x, v, f: 0.0 + fc * tanh(v / fs)
        if has_sf:
            return lambda x, v, f: 0.0 + ss * exp(-((v / sv) ** 2)) * tanh(v / sw)
        if has_off:
            return lambda x, v, f: 0.0 + offset
        if has_rip:
            return lambda x, v, f: 0.0 - rr * sin(_TWO_PI * x / rp + rph) * f
        return lambda x, v, f: 0.0 + stiffness * x

    def effects(x: float, v: float, f: float) -> float:
        total = 0.0
        if has_cog:
            total = total + ca * sin(k * x + cp)
            for hk, ha, hp in harmonics:
                total = total + ha * sin(hk * x + hp)
        if has_cf:
            total = total + fc * tanh(v / fs)
        if has_sf:
            hump = exp(-((v / sv) ** 2))
            total = total + ss * hump * tanh(v / sw)
        if has_off:
            total = total + offset
        if has_rip:
            total = total - rr * sin(_TWO_PI * x / rp + rph) * f
        if has_spring:
            total = total + stiffness * x
        return total

    return effects


class Rk4:
    """Fixed-step RK4 of one plant (see the module docstring of ``motor``).

    ``h_max`` is the longest step; ``tau`` the thrust lag (0: none); ``smoothing`` the
    narrowest sign(v) scale (0: no friction) and ``fric_rate`` the friction's rate near
    v = 0, which decide where a step is split.
    """

    def __init__(self, plant: Plant, h_max: float, effects: EffectForce | None,
                 smoothing: float, fric_rate: float) -> None:
        lag = plant.thrust_lag
        self.h_max = h_max
        self.tau = lag.tau_s if lag is not None else 0.0
        self.inv_m = 1.0 / plant.mass_kg
        self.b = plant.viscous_n_per_mps
        self.lam = self.b * self.inv_m
        self.effects = effects
        self.smoothing = smoothing
        self.fric_rate = fric_rate
        self._coefs: dict[float, tuple[float, float, float, float, float]] = {}

    def coefficients(self, s: float) -> tuple[float, float, float, float, float]:
        """For a step s: the lag's decay over s/2, and exp(-lam t) and the shape of the
        lag response at t = s/2 and t = s (phi(t) = d/M exp(-lam t) shape(t))."""
        got = self._coefs.get(s)
        if got is None:
            tau, lam = self.tau, self.lam
            half = 0.5 * s
            decay_half = math.exp(-0.5 * s / tau) if tau > 0 else 0.0
            if tau > 0.0:
                kappa = 1.0 / tau - lam
                e_mid, e_end = math.exp(-lam * half), math.exp(-lam * s)
                s_mid = half if abs(kappa * half) < 1e-300 else -math.expm1(-kappa * half) / kappa
                s_end = s if abs(kappa * s) < 1e-300 else -math.expm1(-kappa * s) / kappa
            else:
                e_mid = e_end = s_mid = s_end = 0.0
            got = self._coefs[s] = (decay_half, e_mid, s_mid, e_end, s_end)
        return got

    def run(self, x: float, v: float, f: float, duration: float, cmd: float,
            w: float) -> tuple[float, float, float]:
        """(x, v, F) after ``duration`` under the command ``cmd`` and process force ``w``."""
        steps = max(1, math.ceil(duration / self.h_max - 1e-9))
        h = duration / steps
        if self.tau <= 0.0:
            if self.effects is None and self.smoothing <= 0.0:
                return self._run_linear(x, v, steps, h, cmd, w)
            if self.effects is not None:
                return self._run_unlagged(x, v, steps, h, cmd, w, self.effects)
        return self._run_general(x, v, f, steps, h, cmd, w)

    def _run_general(self, x: float, v: float, f: float, steps: int, h: float, cmd: float,
                     w: float) -> tuple[float, float, float]:
        """:meth:`run` for any plant: ``steps`` RK4 steps of ``h`` (what the unlagged paths
        stand for, bit for bit)."""
        tau, inv_m, b, lam, eff = self.tau, self.inv_m, self.b, self.lam, self.effects
        smooth, lagged = self.smoothing, tau > 0.0
        if not lagged:
            f = cmd
        h_coefs = self.coefficients(h)
        near = 5.0 * smooth
        h_rate = h * self.fric_rate
        for _ in range(steps):
            a1 = (f + w - b * v - (eff(x, v, f) if eff is not None else 0.0)) * inv_m
            pieces = 1
            if smooth > 0.0:
                d = f - cmd
                phi = (d * inv_m * h_coefs[3] * h_coefs[4]
                       if d != 0.0 and lagged else 0.0)
                dv = h * (a1 - d * inv_m) + phi
                v_end = v + dv
                if not (min(abs(v), abs(v_end)) > near and v * v_end > 0):
                    need = max(abs(dv) / smooth, h_rate / _NEAR_ZERO_HLAMBDA)
                    pieces = min(_MAX_FINE_STEPS, max(1, math.ceil(need)))
            hp = h if pieces == 1 else h / pieces
            decay_half, e_mid, s_mid, e_end, s_end = (h_coefs if pieces == 1
                                                      else self.coefficients(hp))
            hh, h6 = 0.5 * hp, hp / 6.0
            for j in range(pieces):
                if j:
                    a1 = (f + w - b * v - (eff(x, v, f) if eff is not None else 0.0)) * inv_m
                d = f - cmd
                f_mid = cmd + d * decay_half
                f_end = cmd + d * decay_half * decay_half
                if d == 0.0 or not lagged:
                    phi_mid = phi_end = 0.0
                else:
                    dm = d * inv_m
                    phi_mid = dm * e_mid * s_mid
                    phi_end = dm * e_end * s_end
                mid_fix = lam * phi_mid - (f_mid - cmd) * inv_m
                k1 = a1 - d * inv_m
                v2 = v + hh * k1 + phi_mid
                xa = x + hh * v
                k2 = (f_mid + w - b * v2 - (eff(xa, v2, f_mid) if eff is not None else 0.0)
                      ) * inv_m + mid_fix
                v3 = v + hh * k2 + phi_mid
                xa = x + hh * v2
                k3 = (f_mid + w - b * v3 - (eff(xa, v3, f_mid) if eff is not None else 0.0)
                      ) * inv_m + mid_fix
                v4 = v + hp * k3 + phi_end
                xa = x + hp * v3
                k4 = ((f_end + w - b * v4 - (eff(xa, v4, f_end) if eff is not None else 0.0)
                       ) * inv_m + lam * phi_end - (f_end - cmd) * inv_m)
                x = x + h6 * (v + 2.0 * v2 + 2.0 * v3 + v4)
                v = v + h6 * (k1 + 2.0 * k2 + 2.0 * k3 + k4) + phi_end
                f = f_end
        return x, v, f

    def _run_unlagged(self, x: float, v: float, steps: int, h: float, cmd: float,
                      w: float, eff: EffectForce) -> tuple[float, float, float]:
        """:meth:`run` without a thrust lag, with an effect force ``eff``: the lag terms'
        values written in (d = F - cmd and phi are 0, F(t) = cmd + 0.0), every remaining
        operation as in :meth:`run`, so the numbers are the same bit for bit; measured with
        MotorSimulator.replay, a replayed sample of a plant with Coulomb friction
        12.5 us -> 9.8 us."""
        inv_m, b, smooth = self.inv_m, self.b, self.smoothing
        f, fz = cmd, cmd + 0.0
        mid_fix = self.lam * 0.0 - (fz - cmd) * inv_m
        end_lam, end_fix = self.lam * 0.0, (fz - cmd) * inv_m
        near, h_rate = 5.0 * smooth, h * self.fric_rate
        for _ in range(steps):
            a1 = (f + w - b * v - eff(x, v, f)) * inv_m
            pieces = 1
            if smooth > 0.0:
                dv = h * a1 + 0.0
                v_end = v + dv
                if not (min(abs(v), abs(v_end)) > near and v * v_end > 0):
                    need = max(abs(dv) / smooth, h_rate / _NEAR_ZERO_HLAMBDA)
                    pieces = min(_MAX_FINE_STEPS, max(1, math.ceil(need)))
            hp = h if pieces == 1 else h / pieces
            hh, h6 = 0.5 * hp, hp / 6.0
            for j in range(pieces):
                if j:
                    a1 = (f + w - b * v - eff(x, v, f)) * inv_m
                k1 = a1
                v2 = v + hh * k1 + 0.0
                xa = x + hh * v
                k2 = (fz + w - b * v2 - eff(xa, v2, fz)) * inv_m + mid_fix
                v3 = v + hh * k2 + 0.0
                xa = x + hh * v2
                k3 = (fz + w - b * v3 - eff(xa, v3, fz)) * inv_m + mid_fix
                v4 = v + hp * k3 + 0.0
                xa = x + hp * v3
                k4 = ((fz + w - b * v4 - eff(xa, v4, fz)) * inv_m + end_lam - end_fix)
                x = x + h6 * (v + 2.0 * v2 + 2.0 * v3 + v4)
                v = v + h6 * (k1 + 2.0 * k2 + 2.0 * k3 + k4) + 0.0
                f = fz
        return x, v, f

    def _run_linear(self, x: float, v: float, steps: int, h: float, cmd: float,
                    w: float) -> tuple[float, float, float]:
        """:meth:`_run_unlagged` of a plant without effect force or friction: one piece per
        step, no effect term (subtracting its 0.0 changes no bit); the same numbers;
        measured with MotorSimulator.replay, a replayed sample of the nominal plant
        6.7 us -> 3.2 us."""
        inv_m, b = self.inv_m, self.b
        f, fz = cmd, cmd + 0.0
        mid_fix = self.lam * 0.0 - (fz - cmd) * inv_m
        end_lam, end_fix = self.lam * 0.0, (fz - cmd) * inv_m
        hh, h6 = 0.5 * h, h / 6.0
        for _ in range(steps):
            k1 = (f + w - b * v) * inv_m
            v2 = v + hh * k1 + 0.0
            k2 = (fz + w - b * v2) * inv_m + mid_fix
            v3 = v + hh * k2 + 0.0
            k3 = (fz + w - b * v3) * inv_m + mid_fix
            v4 = v + h * k3 + 0.0
            k4 = (fz + w - b * v4) * inv_m + end_lam - end_fix
            x = x + h6 * (v + 2.0 * v2 + 2.0 * v3 + v4)
            v = v + h6 * (k1 + 2.0 * k2 + 2.0 * k3 + k4) + 0.0
            f = fz
        return x, v, f
