"""The live pipeline's data path without ROS: simulated motor -> window ring -> windows.

:func:`simulated_samples` steps the motor sample by sample exactly as the sim node does
(measure, thrust, advance); :func:`simulated_windows` cuts them with the identifier's
:class:`~.online.WindowScheduler`, so a :class:`~.tracker.WindowTracker` fed from it sees what
``pmsm-sysid run --clock sim`` feeds it when no window is skipped. Deterministic.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from ..physics.excitation import ExcitationSource
from ..physics.motor import MotorSimulator
from ..physics.plant import Plant
from .streaming import NS_PER_S, Sample
from .windows import Window, WindowScheduler

BLOCK = 5000  # excitation samples computed at once


def simulated_samples(plant: Plant, excitation: str, n_samples: int, *, seed: int = 0,
                      amplitude_n: float | None = None,
                      switch: Mapping[int, Plant] | None = None) -> Iterator[Sample]:
    """The ``n_samples`` samples of the motor under ``excitation``, as the sim node publishes
    them; ``switch`` maps a sample index to the plant that takes over from that sample on
    (state kept, as a live parameter change does)."""
    fs = plant.sample_rate_hz
    sim = MotorSimulator(plant, seed=seed)
    src = ExcitationSource(excitation, fs, seed=seed, amplitude_n=amplitude_n)
    switch = switch or {}
    for k0 in range(0, n_samples, BLOCK):
        for j, u in enumerate(src.block(k0, min(BLOCK, n_samples - k0)).tolist()):
            k = k0 + j
            if k in switch:
                sim.set_plant(switch[k])
            speed, position = sim.measure()
            values = (sim.measured_thrust(u), speed, position)
            sim.advance(u)
            yield Sample(k, round(k * NS_PER_S / fs), values)


def simulated_windows(plant: Plant, excitation: str, n_samples: int, *, window: int,
                      hop: int, history: int, seed: int = 0,
                      amplitude_n: float | None = None,
                      switch: Mapping[int, Plant] | None = None) -> Iterator[Window]:
    """Windows of :func:`simulated_samples` (same arguments) cut by the identifier's ring."""
    ring = WindowScheduler(window, hop, history)
    for sample in simulated_samples(plant, excitation, n_samples, seed=seed,
                                    amplitude_n=amplitude_n, switch=switch):
        w = ring.push(sample)
        if w is not None:
            yield w
