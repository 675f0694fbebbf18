"""How often the cross-validation of a correct model fails a window, and what the run verdict
makes of it: simulated data of the ``run`` defaults through the identifier's own data path.

``--duration`` seconds (default 600) of the default plant (``drive``) under the default
excitation (``broadband``, or ``--excitation``) go through the window ring and the
:class:`~pmsm_sysid.core.online.tracker.WindowTracker` with the identifier node's defaults,
as ``pmsm-sysid run --clock sim`` does with no window skipped. Per output it prints the
windows that failed their cross-validation (and which correlation test), the failure rate
beside the rate the tests' own rule gives for white residuals
(:func:`~pmsm_sysid.core.validation.correlation.window_false_rejection_rate`), how many
failed windows have a failed neighbour (the windows overlap: the outcomes of neighbouring
windows are not independent), and the share of runs of 10, 30 and 60 s whose verdict is not
``pass`` (:func:`pmsm_sysid.cli.run_verdict.window_rate`): the verdict's false alarms on a
correct model. ``--set speed.terms=3`` etc. changes an identifier parameter (a model too
small for the plant shows what a wrong structure does). Deterministic.

    .venv/bin/python bench/validation_rate.py [--duration 600] [--excitation broadband]
                                              [--set position.terms=2] [--json FILE]
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from typing import Any

import yaml

from pmsm_sysid.cli.run_verdict import NULL_RATE, window_rate
from pmsm_sysid.core.online.livesim import simulated_windows
from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config
from pmsm_sysid.core.physics.plant import load_plant
from pmsm_sysid.core.validation.correlation import window_false_rejection_rate
from pmsm_sysid.nodes.identifier_node import DEFAULTS

RUNS_S = (10, 30, 60)


def _outcomes(args: argparse.Namespace) -> dict[str, list[dict[str, Any]]]:
    params = dict(DEFAULTS)
    for item in args.set:
        key, _, value = item.partition("=")
        params[key] = yaml.safe_load(value)
    plant = load_plant(args.plant)
    tracker = WindowTracker(tracker_config(params))
    out: dict[str, list[dict[str, Any]]] = collections.defaultdict(list)
    n = round(args.duration * plant.sample_rate_hz)
    for w in simulated_windows(plant, args.excitation, n, window=tracker.config.window,
                               hop=tracker.config.hop, history=tracker.history, seed=args.seed):
        for v in tracker.process(w).validations:
            out[v["output"]].append({
                "pass": bool(v["pass"]), "r2": v["free_run"]["r2"],
                "failed": [k for k, t in v["correlation_tests"].items() if not t["pass"]]})
    return out


def _runs(seq: list[bool], per_run: int) -> tuple[int, int]:
    """(runs whose windows are not consistent with a correct model, runs)."""
    flagged = runs = 0
    for k in range(0, len(seq) - per_run + 1, per_run):
        chunk = seq[k:k + per_run]
        runs += 1
        flagged += not window_rate(sum(chunk), len(chunk))["consistent"]
    return flagged, runs


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--plant", default="drive")
    p.add_argument("--excitation", default="broadband")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    hop_s = DEFAULTS["hop"] / load_plant(args.plant).sample_rate_hz
    result: dict[str, Any] = {"derived_rate": window_false_rejection_rate(),
                              "null_rate": NULL_RATE, "outputs": {}}
    print(f"{args.plant}, {args.excitation}, {args.duration:g} s, {' '.join(args.set)}; "
          f"rate of the tests' rule for white residuals "
          f"{100 * result['derived_rate']:.2f} %, the verdict allows {100 * NULL_RATE:g} %")
    for output, rows in _outcomes(args).items():
        seq = [r["pass"] for r in rows]
        failed = [i for i, ok in enumerate(seq) if not ok]
        paired = sum(1 for i in failed if (i - 1 in failed) or (i + 1 in failed))
        tests = collections.Counter(t for r in rows for t in r["failed"])
        runs = {f"{s} s": _runs(seq, max(1, round(s / hop_s) - 8)) for s in RUNS_S}
        result["outputs"][output] = {"windows": len(seq), "failed": len(failed),
                                     "with_failed_neighbour": paired, "tests": dict(tests),
                                     "runs_not_pass": runs}
        print(f"  {output}: {len(failed)}/{len(seq)} windows failed "
              f"({100 * len(failed) / max(len(seq), 1):.2f} %; {dict(tests)}), "
              f"{paired} of them beside another failed one; runs not judged pass: "
              + ", ".join(f"{k} {a}/{b}" for k, (a, b) in runs.items()))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
