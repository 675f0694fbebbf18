"""How much faster than real time the offline simulator runs: the real-time factor (motor
seconds per second of CPU) of ``simulate`` on three plants, 10 s of motor time each under
the paper's 16.5 Hz speed excitation, median of ``--repeat`` runs. The plants: the nominal
motor, the nominal motor with cogging, Coulomb friction and measurement noise (the slowest
common case: friction near v = 0 makes the integrator take fine steps), and every effect
block at once. Printed beside each: CPU per sample.

    .venv/bin/python bench/simulate_bench.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import CoulombFriction, Noise, Plant, load_plant, nominal_plant

REPO = Path(__file__).resolve().parents[1]


def plants() -> dict[str, Plant]:
    nominal = nominal_plant()
    cogging = load_plant(REPO / "plants" / "cogging.yaml").cogging
    return {
        "nominal": nominal,
        "cogging+coulomb+noise": nominal.with_effects(
            cogging=cogging, coulomb_friction=CoulombFriction(4.0),
            noise=Noise(0.002, 5e-6, 1.0)),
        "all effects": load_plant(REPO / "plants" / "all_effects.yaml"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    for name, plant in plants().items():
        fs = plant.sample_rate_hz
        n = round(10.0 * fs)
        u = 50 * np.sin(2 * np.pi * 16.5 * np.arange(n) / fs)
        cpu = []
        for _ in range(args.repeat):
            started = time.process_time()
            simulate(plant, u)
            cpu.append(time.process_time() - started)
        med = statistics.median(cpu)
        print(f"{name:24s} {n / fs / med:7.1f}x real time  ({1e6 * med / n:.1f} us CPU per sample)")


if __name__ == "__main__":
    main()
