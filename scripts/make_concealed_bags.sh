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
