"""How ``diagnose`` scales with the length of the recording: time, CPU time and peak memory.

Recordings of 12 s, 60 s, 600 s and 3600 s (default 1 kHz: up to 3.6 million samples) are
simulated with ``pmsm-sysid simulate`` into bags on disk (the concealed-cogging plant --
0.6 N at a 7 mm pitch, speed noise 2 mm/s, process force 1 N -- driven by the paper's
position excitation), read back and diagnosed against the nominal plant by ``pmsm-sysid
diagnose``, each in its own process, so the peak memory (``ru_maxrss`` of that process,
from ``wait4``) and the CPU time (user + system) are the command's own. The machine may be
shared and busy: the CPU time is the figure to compare, the wall time is printed beside it.

The table gives, per length, what part of the recording was used, the time and memory of
``simulate`` (bounded too: it writes the bag block by block) and of ``diagnose``, the CPU
time per second of data and its ratio to the shortest recording's (below 1: better than
linear), and what was found (the truth: cogging 0.6 N at 7 mm). ``--baseline-tree DIR``
runs the same diagnoses with the package of another checkout (e.g. the main branch before
this change) in the same run and prints the ratios (on recordings up to ``--baseline-max``
seconds: a baseline that holds the whole recording may need many GB).

    python bench/diagnose_scaling.py [--lengths 12,60,600,3600] [--rate 1000]
        [--dir DIR] [--baseline-tree DIR] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from pmsm_sysid.core.physics.plant import dump_plant, load_plant

REPO = Path(__file__).resolve().parents[1]
PLANT = REPO / "plants" / "concealed_cogging.yaml"
NOMINAL = REPO / "plants" / "nominal.yaml"


def measured(cmd: list[str], env: dict[str, str]) -> dict[str, Any]:
    """Run ``cmd``; its wall time, CPU time (s) and peak resident memory (MB)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    out = proc.stdout.read().decode() if proc.stdout else ""
    err = proc.stderr.read().decode() if proc.stderr else ""
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({code}): {err.strip()[-2000:]}")
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
            "peak_mb": usage.ru_maxrss / 1024.0, "stdout": out}


def cli(tree: Path | None) -> tuple[list[str], dict[str, str]]:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}  # one BLAS thread, as `make test`
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    return [sys.executable, "-m", "pmsm_sysid.cli"], env


def make_bag(root: Path, plant_file: Path, seconds: float,
             rate: float) -> tuple[Path, dict[str, Any]]:
    bag = root / f"cogging_{rate:g}hz_{seconds:g}s"
    if bag.exists():
        return bag, {}
    cmd, env = cli(None)
    got = measured([*cmd, "simulate", "--plant", str(plant_file), "--excitation",
                    "paper-position", "--duration", f"{seconds:g}", "--seed", "1",
                    "--out", str(bag), "--quiet"], env)
    return bag, got


def diagnose(bag: Path, out: Path, tree: Path | None) -> dict[str, Any]:
    cmd, env = cli(tree)
    out.unlink(missing_ok=True)
    got = measured([*cmd, "diagnose", "--plant", str(NOMINAL), "--real", str(bag),
                    "--json", str(out), "--quiet"], env)
    result = json.loads(out.read_text())
    used = (result["method"].get("data_used") or {}).get("recording") or {}
    found = []
    for e in result["effects"]:
        p = e["params"]
        what = (f"{e['name']} {p['amplitude_n']:.3f} N at {1e3 * p['pitch_m']:.3f} mm"
                if e["name"] == "cogging" else e["name"])
        found.append(f"{what} ({e.get('confidence', '?')})")
    got.update(found=found, used=used.get("samples"), used_text=used.get("text", "all"))
    return got


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lengths", default="12,60,600,3600", help="seconds, comma-separated")
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate (Hz)")
    ap.add_argument("--dir", type=Path, default=None,
                    help="keep the bags here and reuse them (default: a temporary directory)")
    ap.add_argument("--baseline-tree", type=Path, default=None,
                    help="also diagnose with the package of this checkout (ratios printed)")
    ap.add_argument("--baseline-max", type=float, default=60.0,
                    help="longest recording (s) the baseline is run on (default 60: the "
                         "whole-recording baseline of a long one may need many GB)")
    ap.add_argument("--json", type=Path, default=None, help="write the figures as JSON")
    args = ap.parse_args()
    lengths = [float(x) for x in args.lengths.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        root = args.dir or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        plant_file = root / f"concealed_cogging_{args.rate:g}hz.yaml"
        plant_file.write_text(dump_plant(replace(load_plant(PLANT), sample_rate_hz=args.rate)))
        rows = []
        for seconds in lengths:
            bag, sim = make_bag(root, plant_file, seconds, args.rate)
            row: dict[str, Any] = {"seconds": seconds, "samples": round(seconds * args.rate),
                                   "simulate": sim, "diagnose": diagnose(bag, root / "d.json",
                                                                         None)}
            if args.baseline_tree is not None and seconds <= args.baseline_max:
                row["baseline"] = diagnose(bag, root / "b.json", args.baseline_tree)
            rows.append(row)
            print(f"{seconds:g} s done: {row['diagnose']['cpu_s']:.1f} s CPU, "
                  f"{row['diagnose']['peak_mb']:.0f} MB", file=sys.stderr, flush=True)
    report(rows, args.baseline_tree)
    if args.json:
        args.json.write_text(json.dumps({"rate_hz": args.rate, "rows": rows}, indent=1,
                                        default=str))
    return 0


def report(rows: list[dict[str, Any]], baseline: Path | None) -> None:
    first = rows[0]["diagnose"]["cpu_s"] / rows[0]["seconds"]
    print("| length | samples | used | simulate CPU / peak | diagnose wall | CPU | peak | "
          "CPU per s of data | vs shortest | found |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        d, s = r["diagnose"], r["simulate"]
        per = d["cpu_s"] / r["seconds"]
        sim = f"{s['cpu_s']:.0f} s / {s['peak_mb']:.0f} MB" if s else "(reused)"
        print(f"| {r['seconds']:g} s | {r['samples']} | {d['used']} | {sim} | "
              f"{d['wall_s']:.1f} s | {d['cpu_s']:.1f} s | {d['peak_mb']:.0f} MB | "
              f"{1e3 * per:.0f} ms | {per / first:.3f} | {'; '.join(d['found']) or 'nothing'} |")
    if baseline is None:
        return
    print(f"\nbaseline: {baseline}")
    print("| length | baseline CPU | peak | CPU ratio (this / baseline) | peak ratio | found |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        if "baseline" not in r:
            continue
        b, d = r["baseline"], r["diagnose"]
        print(f"| {r['seconds']:g} s | {b['cpu_s']:.1f} s | {b['peak_mb']:.0f} MB | "
              f"{d['cpu_s'] / b['cpu_s']:.3f} | {d['peak_mb'] / b['peak_mb']:.3f} | "
              f"{'; '.join(b['found']) or 'nothing'} |")


if __name__ == "__main__":
    sys.exit(main())
