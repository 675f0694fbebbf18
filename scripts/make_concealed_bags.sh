#!/usr/bin/env bash
# Regenerates the concealed-effect recordings bags/concealed_* and their true plants
# plants/concealed_*.yaml (pmsm_sysid.core.discrepancy.scenarios): cogging under the speed
# noise, friction hidden by a position loop, the winding lag (a fifth of a sample), two
# effects at once, and the nominal motor itself. Deterministic: same seeds, same bytes.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
"$PY" scripts/make_concealed_bags.py bags plants
du -sh bags/concealed_* | sort -k2
# the simulator-against-drive pair of the README (a JointState simulator at 1 kHz, a real
# axis at 500 Hz under a position loop)
"$PY" scripts/make_sim_real_bags.py bags plants
du -sh bags/sim_axis bags/real_axis bags/real_axis_validate
