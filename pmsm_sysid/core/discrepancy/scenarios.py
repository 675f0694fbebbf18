"""Concealed-effect recordings: known plants whose missing physics hides in the data.

Each scenario is the nominal motor of the paper's Table 1 plus one or two effects, realistic
noise (speed 2 mm/s, position 5 um, process force 1 N, 1 um encoder steps) and a drive that
hides the effect: open loop with the paper's excitations, or under a PID position loop whose
thrust is recorded (as on the EMPS rig). ``scripts/make_concealed_bags.sh`` writes them to
``bags/concealed_*`` with their true plants in ``plants/concealed_*.yaml``; the tests
regenerate them in memory with other seeds. ``TRUTH`` lists what ``diagnose`` must find
and the tolerances it is held to.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import DiagnoseError
from ..physics.closed_loop import PositionLoop, reference_trajectory, run_closed_loop
from ..physics.excitation import make_excitation
from ..physics.motor import simulate
from ..physics.plant import (
    Cogging,
    CoulombFriction,
    Noise,
    Plant,
    Quantisation,
    StribeckFriction,
    electrical_lag,
    nominal_plant,
)
from ..recording.signals import Recording

NOISE = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0)
QUANT = Quantisation(position_m=1e-6)
FS = 500.0
DURATION_S = 5.0
LOOP_HZ = 15.0


@dataclass(frozen=True)
class Scenario:
    """A plant, how it is driven, and the random seed of the committed bag."""

    name: str
    plant: Plant
    drive: str  # "paper-position" | "paper-speed" | "position-loop"
    description: str
    seed: int = 1
    reference: tuple[tuple[float, ...], tuple[float, ...]] = ((0.02, 0.004), (0.4, 1.7))
    truth: dict[str, dict[str, Any]] = field(default_factory=dict)


def _noisy(**blocks: Any) -> Plant:
    return nominal_plant().with_effects(noise=NOISE, quantisation=QUANT, **blocks)


SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    Scenario("nominal", _noisy(), "paper-position",
             "the nominal motor itself, noise only: nothing may be named"),
    Scenario("cogging", _noisy(cogging=Cogging(0.6, 0.007, 1.1)), "paper-position",
             "cogging 0.6 N (2 % of the 28 N rms thrust) at a 7 mm pitch, open loop: below "
             "the speed noise"),
    Scenario("friction", _noisy(coulomb_friction=CoulombFriction(2.5),
                                stribeck_friction=StribeckFriction(1.5, 0.01)),
             "position-loop",
             "Coulomb 2.5 N plus a 1.5 N Stribeck hump (vs = 10 mm/s) under a 15 Hz PID "
             "position loop: the position tracks, the thrust hides the friction"),
    Scenario("lag", _noisy(thrust_lag=electrical_lag(nominal_plant())), "paper-speed",
             "the winding lag L/R = 0.41 ms, a fifth of the 2 ms sample period, open loop"),
    Scenario("two", _noisy(cogging=Cogging(1.0, 0.006, 0.4),
                           coulomb_friction=CoulombFriction(2.0)), "position-loop",
             "cogging 1 N at 6 mm and Coulomb 2 N at once, under the position loop"),
)}

TRUTH_TOLERANCE = {"pitch_m": 0.02, "amplitude_n": 0.20, "coulomb": 0.10, "tau_s": 0.25}


def make_recording(name: str, seed: int | None = None, duration_s: float = DURATION_S,
                   phase_shift: float = 0.0) -> Recording:
    """The scenario's recording (``seed`` None: the committed bag's seed)."""
    if name not in SCENARIOS:
        raise DiagnoseError(f"unknown scenario '{name}'; known: {', '.join(SCENARIOS)}")
    sc = SCENARIOS[name]
    seed = sc.seed if seed is None else seed
    n = round(duration_s * FS)
    if sc.drive == "position-loop":
        amps, freqs = sc.reference
        ref = reference_trajectory(n, FS, amps, freqs)
        if phase_shift:
            ref = reference_trajectory(n, FS, amps, tuple(f * (1 + phase_shift) for f in freqs))
        loop = PositionLoop.for_bandwidth(nominal_plant(), LOOP_HZ)
        return run_closed_loop(sc.plant, ref, loop, seed=seed)
    thrust = make_excitation(sc.drive, n, FS, seed=seed)
    return simulate(sc.plant, thrust, seed=seed)
