"""Write the concealed-effect recordings of pmsm_sysid.core.discrepancy.scenarios to bags/.

Usage: python scripts/make_concealed_bags.py [OUT_DIR] [PLANT_DIR]  (defaults: bags, plants)
Each scenario but 'nominal' becomes bags/concealed_<name> (mcap, 5 s at 500 Hz, the
scenario's seed) and its true plant plants/concealed_<name>.yaml. The 'two' scenario also
gets a held-out recording bags/concealed_two_validate (another seed, a 10 % faster
reference). The nominal scenario is only simulated in the tests (bags/paper_speed_nominal
is the committed noise-only recording), to keep bags/ small.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from pmsm_sysid.bagio import write_recording
from pmsm_sysid.core.discrepancy.scenarios import SCENARIOS, make_recording
from pmsm_sysid.core.physics.plant import dump_plant


def main() -> int:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "bags")
    plants = Path(sys.argv[2] if len(sys.argv) > 2 else "plants")
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(name, make_recording(name)) for name in SCENARIOS if name != "nominal"]
    jobs.append(("two_validate", make_recording("two", seed=7, phase_shift=0.1)))
    for name, rec in jobs:
        bag = out / f"concealed_{name}"
        if bag.exists():
            shutil.rmtree(bag)
        scenario = SCENARIOS[name.removesuffix("_validate")]
        write_recording(bag, rec, storage="mcap",
                        custom_data={"pmsm_sysid.scenario": scenario.description})
        if not name.endswith("_validate"):
            header = (f"# Concealed-effect scenario '{name}': {scenario.description}.\n"
                      f"# The true plant of bags/concealed_{name} (drive: {scenario.drive}, "
                      f"seed {scenario.seed}); written by scripts/make_concealed_bags.sh.\n")
            (plants / f"concealed_{name}.yaml").write_text(header + dump_plant(scenario.plant))
        print(f"wrote {bag} ({len(rec)} samples)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
