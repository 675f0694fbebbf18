"""False alarms of the live change detector: simulated data of a plant that never changes.

For every packaged excitation, ``--duration`` seconds (default one hour) of the simulated
motor (``--plant``, default the ``run`` default ``drive``; seed ``--seed``) go sample by
sample through the identifier's own data path, without ROS: the window ring
(:class:`~pmsm_sysid.core.online.windows.WindowScheduler`) cuts a window every hop and the
:class:`~pmsm_sysid.core.online.tracker.WindowTracker` with the identifier node's default
parameters fits, cross-validates and judges it, as ``pmsm-sysid run`` does with no window
skipped (the simulated clock). Deterministic: same plant, seed and duration, same table.

Per excitation and output it counts the change events (every one is a false alarm: the
plant is stationary), the share of windows the detector judged (a detector that never judges
has no false alarms: ``unjudged`` windows are those whose models do not reproduce their own
window, median free-run R2 < 0.99, or whose input spectrum is not the reference window's),
the share of cross-validations that passed, and the windows with data-check warnings and
with fit errors.

    .venv/bin/python bench/change_false_alarms.py [--duration 3600] [--jobs 2]
                                                  [--excitations broadband,paper-speed]
                                                  [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from pmsm_sysid.core.online.livesim import simulated_windows
from pmsm_sysid.core.online.tracker import WindowResult, WindowTracker, tracker_config
from pmsm_sysid.core.physics.excitation import EXCITATIONS
from pmsm_sysid.core.physics.plant import load_plant
from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS as DEFAULTS


def _new_counts() -> dict[str, Any]:
    return {"windows": 0, "judged": 0, "changes": [], "validations": 0, "passed": 0,
            "warned": 0, "errors": 0}


def _tally(r: WindowResult, out: dict[str, dict[str, Any]]) -> None:
    for d in r.decisions:
        c = out[d["output"]]
        c["windows"] += 1
        c["judged"] += d["state"] in ("steady", "change")
    for ch in r.changes:
        out[ch["output"]]["changes"].append(
            {"t_s": ch["window"]["end_stamp"], "reasons": ch["reasons"]})
    for v in r.validations:
        out[v["output"]]["validations"] += 1
        out[v["output"]]["passed"] += bool(v["pass"])
    for m in r.models:
        out[m["output"]]["warned"] += bool((m.get("data_check") or {}).get("warnings"))
    for e in r.errors:
        out[e["output"]]["errors"] += 1


def run_one(kind: str, duration_s: float, plant_name: str, seed: int,
            params: dict[str, Any], progress_s: float = 0.0) -> dict[str, Any]:
    """Stream ``duration_s`` of ``kind`` through the tracker; counts per output. Every
    ``progress_s`` seconds of data (0 = never) one line on stderr says how far it got."""
    t0 = time.perf_counter()
    plant = load_plant(plant_name)
    fs = plant.sample_rate_hz
    tracker = WindowTracker(tracker_config({**DEFAULTS, **params}))
    cfg = tracker.config
    counts = {o.output: _new_counts() for o in cfg.outputs}
    n = round(duration_s * fs)
    every = round(progress_s * fs / cfg.hop) * cfg.hop if progress_s > 0 else 0
    for w in simulated_windows(plant, kind, n, window=cfg.window, hop=cfg.hop,
                               history=tracker.history, seed=seed):
        _tally(tracker.process(w), counts)
        if every and w.stop_index % every == 0:
            alarms = {o: len(c["changes"]) for o, c in counts.items()}
            print(f"{kind}: {w.stop_index / fs:.0f} s of data, false alarms {alarms}, "
                  f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return {"excitation": kind, "duration_s": n / fs, "plant": plant_name,
            "seed": seed, "outputs": counts, "cpu_s": time.perf_counter() - t0}


def table(results: list[dict[str, Any]]) -> str:
    """Markdown table: one row per excitation and output."""
    head = ("| excitation | output | windows | judged | false alarms | per hour "
            "| validation pass | data-check warnings | fit errors |")
    rows = [head, "|" + "---|" * 9]
    for r in results:
        hours = r["duration_s"] / 3600.0
        for name, c in r["outputs"].items():
            w = max(c["windows"], 1)
            rows.append(
                f"| {r['excitation']} | {name} | {c['windows']} | "
                f"{100 * c['judged'] / w:.0f} % | {len(c['changes'])} | "
                f"{len(c['changes']) / hours:.2f} | "
                f"{c['passed']}/{c['validations']} | {c['warned']} | {c['errors']} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="seconds of data each")
    ap.add_argument("--excitations", default=",".join(EXCITATIONS))
    ap.add_argument("--plant", default="drive")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1, help="excitations run in parallel")
    ap.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE",
                    help="identifier parameter, e.g. method=iofr (repeatable)")
    ap.add_argument("--json", metavar="FILE", help="write the counts (and every alarm)")
    ap.add_argument("--progress", type=float, default=0.0, metavar="S",
                    help="a progress line every S seconds of data (default: none)")
    args = ap.parse_args(argv)
    kinds = [k.strip() for k in args.excitations.split(",") if k.strip()]
    bad = [k for k in kinds if k not in EXCITATIONS]
    if bad or not args.duration > 0 or args.jobs < 1:
        print(f"change_false_alarms: need excitations from {', '.join(EXCITATIONS)}, "
              f"--duration > 0 and --jobs >= 1", file=sys.stderr)
        return 2
    import yaml

    params = {}
    for item in args.set:
        key, _, text = item.partition("=")
        params[key] = yaml.safe_load(text)
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(run_one, k, args.duration, args.plant, args.seed, params,
                               args.progress)
                   for k in kinds]
        results = [f.result() for f in futures]
    print(f"plant {args.plant}, seed {args.seed}, {args.duration:g} s of data per "
          f"excitation, identifier defaults{' + ' + ', '.join(args.set) if args.set else ''}")
    print(table(results))
    for r in results:
        for name, c in r["outputs"].items():
            for ch in c["changes"]:
                print(f"  {r['excitation']} {name}: change at {ch['t_s']:.1f} s "
                      f"({', '.join(ch['reasons'])})")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
