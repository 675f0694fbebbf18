#!/usr/bin/env bash
# Regenerates the sample recordings in bags/ (listed in bags/README.md) with the project's
# own simulator: the paper's speed experiment (16.5 Hz thrust, 500 Hz) for 9 s = 4500
# samples, on three plant files from plants/ that share one noise block and one seed, so
# the bags differ only by the effect each one adds.
set -euo pipefail
cd "$(dirname "$0")/.."
CLI=${PMSM_SYSID:-.venv/bin/pmsm-sysid}
DURATION=9
SEED=1

make_bag() {  # name plant-file
    "$CLI" simulate --plant "plants/$2" --excitation paper-speed --duration "$DURATION" \
        --seed "$SEED" --storage mcap --out "bags/$1" --force
}

mkdir -p bags
make_bag paper_speed_nominal nominal_noisy.yaml
make_bag paper_speed_cogging cogging.yaml
make_bag paper_speed_coulomb coulomb.yaml
du -sh bags
