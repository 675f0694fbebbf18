#!/usr/bin/env bash
# The main job end to end on the bundled default recording (called by `make demo`).
set -euo pipefail
OUT=${1:-demo_out}
CLI=.venv/bin/pmsm-sysid
mkdir -p "$OUT"
# the demo's own outputs are replaced on every run (--force): `make demo` may be run again
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
step() { printf '\n== %s\n' "$*"; }

step "1/5 live pipeline, defaults: simulated drive (Table 1 motor, 1 um scale noise, broadband thrust) + identifier + GFRF in one process (10 s)"
rm -rf "$OUT/live_bag"
$CLI run --duration 10 --record "$OUT/live_bag" --json "$OUT/run.json" --force

step "2/5 offline identification of the bundled recording (paper's speed protocol)"
$CLI identify bags/paper_speed_nominal --json "$OUT/identify.json" --force

step "3/5 GFRFs and ridges of that model"
$CLI gfrf "$OUT/identify.json" --json "$OUT/gfrf.json" --force

step "4/5 sim-to-real: what does the nominal plant miss in the cogging recording?"
$CLI diagnose --plant plants/nominal.yaml --real bags/paper_speed_cogging --json "$OUT/diagnose.json" \
  --force

step "5/5 report"
if $CLI report --help >/dev/null 2>&1; then
  $CLI report "$OUT/identify.json" --out "$OUT/report" --force
  $CLI report "$OUT/diagnose.json" --out "$OUT/diagnose_report" --force
fi
echo
echo "demo outputs in $(realpath -m "$OUT")"
