"""Offline simulation of the motor: :func:`simulate` (faster than real time, no ROS)."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..core.errors import OptionError
from ..core.physics.excitation import EXCITATIONS, ExcitationSource
from ..core.physics.plant import Plant, load_plant, nominal_plant
from ..core.recording.signals import Recording
from ..validate import MAX_AMPLITUDE_N, check_duration, check_number, check_seed
from . import _checks

PlantLike = Plant | str | os.PathLike[str] | None


def resolve_plant(plant: PlantLike) -> tuple[Plant, str]:
    """The plant and how to name it: ``nominal``, the file as given, or ``Plant object``."""
    if plant is None:
        return nominal_plant(), "nominal"
    if isinstance(plant, Plant):
        return plant, "Plant object"
    if isinstance(plant, (str, os.PathLike)):
        return load_plant(Path(plant)), str(plant)
    raise OptionError(f"plant must be None, a Plant or a plant YAML path, got "
                      f"{type(plant).__name__}")


@dataclass(frozen=True)
class SimulationRun:
    """A simulated recording with the plant and excitation that made it (for the CLI)."""

    recording: Recording
    plant: Plant
    plant_label: str
    source: ExcitationSource


@dataclass(frozen=True)
class SimulationPlan:
    """A checked simulation not run yet: :meth:`blocks` runs it a block at a time."""

    plant: Plant
    plant_label: str
    source: ExcitationSource
    samples: int
    seed: int

    def meta(self, rec: Recording) -> dict[str, str]:
        """The recording's metadata: the simulator's plus the excitation and plant file."""
        return {**rec.meta, "excitation": self.source.kind,
                "excitation_amplitude_n": repr(self.source.amplitude_n),
                "excitation_options": json.dumps(self.source.options, sort_keys=True),
                "plant_file": self.plant_label}

    def blocks(self, block: int | None = None) -> Iterator[Recording]:
        """The recording in consecutive blocks (the numbers of :func:`simulate`)."""
        from ..core.physics.motor import BLOCK, simulate_blocks

        for rec in simulate_blocks(self.plant, self.source.block, self.samples, self.seed,
                                   block or BLOCK):
            yield replace(rec, meta=self.meta(rec))


def simulation_plan(plant: PlantLike = None, *, excitation: str = "paper-speed",
                    duration: float = 10.0, seed: int = 0, amplitude: float | None = None,
                    excitation_options: Mapping[str, Any] | None = None) -> SimulationPlan:
    """The options of :func:`simulate`, checked, and what they will run."""
    _checks.choice("excitation", excitation, EXCITATIONS)
    seconds = _checks.positive("duration", duration)
    check_seed(seed, "seed")
    if amplitude is not None:
        check_number("amplitude", amplitude, low=0, high=MAX_AMPLITUDE_N, unit="N")
    model, label = resolve_plant(plant)
    fs = model.sample_rate_hz
    check_duration(seconds, "duration", rate_hz=fs)  # at most MAX_SAMPLES samples
    n = max(2, round(seconds * fs))
    source = ExcitationSource(excitation, fs, seed=seed, amplitude_n=amplitude,
                              **dict(excitation_options or {}))
    return SimulationPlan(model, label, source, n, seed)


def simulation_run(plant: PlantLike = None, *, excitation: str = "paper-speed",
                   duration: float = 10.0, seed: int = 0, amplitude: float | None = None,
                   excitation_options: Mapping[str, Any] | None = None) -> SimulationRun:
    """:func:`simulate`, keeping the plant and the excitation source."""
    from ..core.physics.motor import simulate as integrate

    plan = simulation_plan(plant, excitation=excitation, duration=duration, seed=seed,
                           amplitude=amplitude, excitation_options=excitation_options)
    rec = integrate(plan.plant, plan.source.block(0, plan.samples), seed=seed)
    return SimulationRun(replace(rec, meta=plan.meta(rec)), plan.plant, plan.plant_label,
                         plan.source)


def simulate(plant: PlantLike = None, *, excitation: str = "paper-speed",
             duration: float = 10.0, seed: int = 0, amplitude: float | None = None,
             excitation_options: Mapping[str, Any] | None = None) -> Recording:
    """Simulate the linear motor under a thrust excitation and return the recording.

    ``plant``: ``None`` for the nominal motor of the paper's Table 1 (M = 2.3213 kg,
    B = 32.4992 N s/m, 500 Hz), a :class:`Plant`, or the path of a YAML plant file with
    optional effects (cogging, friction, thrust lag, delay, noise, ...).
    ``excitation``: ``paper-speed`` (16.5 Hz sine), ``paper-position`` (11.5 Hz),
    ``multisine``, ``chirp``, ``prbs`` or ``aprbs``; ``amplitude`` is the peak thrust in N
    (default depends on the excitation); ``excitation_options`` are the excitation's own
    keys, e.g. ``{"f_max_hz": 60}``. ``duration`` in seconds. ``seed`` fixes the noise and
    the random excitations: the same arguments give the same recording.

    Same numbers as ``pmsm-sysid simulate`` with the same options; write the result with
    :func:`write_bag`.

    Example:
        >>> import pmsm_sysid as ps
        >>> rec = ps.simulate(duration=2.0, seed=1)
        >>> len(rec), rec.sample_rate_hz
        (1000, 500.0)
        >>> import dataclasses  # a Plant is a frozen dataclass
        >>> heavier = dataclasses.replace(ps.Plant.nominal(), mass_kg=4.0)
        >>> bool(abs(ps.simulate(heavier, duration=2.0).speed).max() < abs(rec.speed).max())
        True
    """
    return simulation_run(plant, excitation=excitation, duration=duration, seed=seed,
                          amplitude=amplitude, excitation_options=excitation_options).recording
