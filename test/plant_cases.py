"""Known-truth recordings for fitting plants and comparing recordings (the project's simulator).

A "simulator" plant that is not the nominal one (3.1 kg, 25 N s/m) recorded at 1 kHz, and
"real" variants of it at 500 Hz, open loop or under a PID position loop, all with realistic
noise on every signal: speed 2 mm/s, position 5 µm (1 µm encoder steps), a 1 N process
force and, where asked, 2 N of noise on the thrust reading itself. Under the loop an
excitation may be injected into the controller's output (closed-loop identification).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from pmsm_sysid.core.physics.closed_loop import (
    PositionLoop,
    reference_trajectory,
    run_closed_loop,
)
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import Noise, Plant, Quantisation
from pmsm_sysid.core.recording.signals import Recording

SIM_MASS, SIM_VISCOUS = 3.1, 25.0
NOISE = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0)
THRUST_NOISE = replace(NOISE, thrust_std=2.0)
QUANT = Quantisation(position_m=1e-6)


def plant(fs: float = 1000.0, thrust_noise: bool = False, **blocks: Any) -> Plant:
    """The simulator's plant (3.1 kg, 25 N s/m) with noise, at ``fs``, plus ``blocks``."""
    base = Plant(mass_kg=SIM_MASS, viscous_n_per_mps=SIM_VISCOUS, sample_rate_hz=fs,
                 noise=THRUST_NOISE if thrust_noise else NOISE, quantisation=QUANT)
    return replace(base, **blocks)


def open_loop(p: Plant, excitation: str, seconds: float, seed: int) -> Recording:
    """``p`` driven by ``excitation`` for ``seconds``."""
    n = round(seconds * p.sample_rate_hz)
    return simulate(p, make_excitation(excitation, n, p.sample_rate_hz, seed=seed), seed=seed)


def closed_loop(p: Plant, seconds: float, seed: int, faster: float = 1.0,
                inject: str | None = None, amplitude: float = 6.0) -> Recording:
    """``p`` under a 15 Hz PID position loop following a two-sine move (20 mm at 0.4 Hz,
    4 mm at 1.7 Hz; ``faster`` scales both frequencies), with ``inject`` (an excitation
    of ``amplitude`` N) added to the controller's output and recorded with it."""
    n = round(seconds * p.sample_rate_hz)
    ref = reference_trajectory(n, p.sample_rate_hz, (0.02, 0.004),
                               (0.4 * faster, 1.7 * faster))
    loop = PositionLoop.for_bandwidth(replace(p, noise=None), 15.0)
    exc = None if inject is None else make_excitation(inject, n, p.sample_rate_hz,
                                                      seed=seed, amplitude_n=amplitude)
    return run_closed_loop(p, ref, loop, seed=seed, injection=exc)
