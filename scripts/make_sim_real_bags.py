"""Write the "your simulator against your drive" sample recordings to bags/.

Usage: python scripts/make_sim_real_bags.py [OUT_DIR] [PLANT_DIR]  (defaults: bags, plants)

* ``bags/sim_axis`` -- a simulator's recording as ros2_control publishes it (one
  ``sensor_msgs/JointState`` topic ``/joint_states``, joint ``axis``): a 3.1 kg, 25 N s/m
  axis (not the paper's motor) driven open loop by a 30 N chirp at 1 kHz for 5 s, with the
  sensor noise a simulator's plugins add. True plant: ``plants/sim_axis.yaml``.
* ``bags/real_axis`` and ``bags/real_axis_validate`` (another seed) -- the "real" drive:
  6.5 % heavier, 2 N of Coulomb friction and a 0.8 N cogging at a 6 mm pitch, none of which
  the simulator has, recorded as the three ``/pmsm`` topics at 500 Hz for 5 s under a 15 Hz
  PID position loop with a 20 N chirp injected into the controller's output, noise on every
  signal (0.5 N on the thrust reading too). True plant: ``plants/real_axis.yaml``.

Deterministic: same seeds, same bytes.
"""

from __future__ import annotations

import shutil
import sys
from dataclasses import replace
from pathlib import Path

from pmsm_sysid.bagio import write_joint_states, write_recording
from pmsm_sysid.core.physics.closed_loop import PositionLoop, reference_trajectory, run_closed_loop
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import (
    Cogging,
    CoulombFriction,
    Noise,
    Plant,
    Quantisation,
    dump_plant,
)
from pmsm_sysid.core.recording.signals import Recording

SECONDS = 5.0
SIM = Plant(mass_kg=3.1, viscous_n_per_mps=25.0, sample_rate_hz=1000.0,
            noise=Noise(speed_std=0.001, position_std=2e-6), quantisation=Quantisation(1e-6))
REAL = Plant(mass_kg=3.3, viscous_n_per_mps=25.0, sample_rate_hz=500.0,
             coulomb_friction=CoulombFriction(2.0), cogging=Cogging(0.8, 0.006, 0.3),
             noise=Noise(speed_std=0.002, position_std=5e-6, force_std=1.0, thrust_std=0.5),
             quantisation=Quantisation(1e-6))


def sim_axis() -> Recording:
    n = round(SECONDS * SIM.sample_rate_hz)
    return simulate(SIM, make_excitation("chirp", n, SIM.sample_rate_hz, seed=1), seed=1)


def real_axis(seed: int) -> Recording:
    fs = REAL.sample_rate_hz
    n = round(SECONDS * fs)
    ref = reference_trajectory(n, fs, (0.02, 0.004), (0.4, 1.7))
    loop = PositionLoop.for_bandwidth(replace(REAL, noise=None), 15.0)
    exc = make_excitation("chirp", n, fs, seed=seed, amplitude_n=20.0)
    return run_closed_loop(REAL, ref, loop, seed=seed, injection=exc)


def main() -> int:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "bags")
    plants = Path(sys.argv[2] if len(sys.argv) > 2 else "plants")
    out.mkdir(parents=True, exist_ok=True)
    for name in ("sim_axis", "real_axis", "real_axis_validate"):
        if (out / name).exists():
            shutil.rmtree(out / name)
    write_joint_states(out / "sim_axis", sim_axis())
    write_recording(out / "real_axis", real_axis(3))
    write_recording(out / "real_axis_validate", real_axis(4))
    for name, plant, what in (
            ("sim_axis", SIM, "the simulator's axis of bags/sim_axis (JointState, 1 kHz, "
                              "open-loop chirp)"),
            ("real_axis", REAL, "the real axis of bags/real_axis and real_axis_validate "
                                "(topics, 500 Hz, position loop with a chirp injected)")):
        (plants / f"{name}.yaml").write_text(
            f"# True plant of {what};\n# written by scripts/make_sim_real_bags.py.\n"
            + dump_plant(plant))
    print(f"wrote {out}/sim_axis, {out}/real_axis, {out}/real_axis_validate")
    return 0


if __name__ == "__main__":
    sys.exit(main())
