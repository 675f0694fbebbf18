"""Sim-clock speed: ``pmsm-sysid run --clock sim --duration 60`` against real time.

Runs the verb as a user does (its own process: the default plant and excitation, speed and
position models, GFRF node) ``--repeat`` times and prints, for each run and for the best,
the simulated seconds per wall second (the speed against real time, which runs 1 s of data
per second; target: at least 10x on an idle machine), the wall time, the CPU seconds of the
run and its worker processes (main process and workers apart, from the run's own counters)
and the machine's load average at the start: other work on a shared machine slows the run
and is printed with it. Every window must be fitted (none skipped) for a run to count.

With ``--baseline DIR`` (another checkout of the package, e.g. ``git worktree add /tmp/base
main``) the runs alternate between that code and this one (same interpreter and
dependencies, the package taken from DIR through PYTHONPATH), and the medians of both are
printed: on a shared machine only interleaved runs compare.

Usage: ``python bench/sim_clock_bench.py [--duration 60] [--repeat 3] [--baseline DIR]
[--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
TARGET = 10.0  # simulated seconds per wall second on an idle machine


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def one_run(duration: float, env: dict[str, str]) -> dict[str, Any]:
    """One ``run --clock sim``: wall, speed, CPU (the run and every process it waited for)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        load = os.getloadavg()[0]
        cpu0, t0 = _children_cpu(), time.monotonic()
        # from a directory of its own: ``-m`` puts the working directory first on sys.path,
        # which from a checkout's root would import that checkout, whatever PYTHONPATH says
        proc = subprocess.run([sys.executable, "-m", "pmsm_sysid.cli", "run", "--clock", "sim",
                               "--duration", str(duration), "--json", str(out)], env=env,
                              cwd=tmp, capture_output=True, text=True, timeout=1800)
        wall, cpu = time.monotonic() - t0, _children_cpu() - cpu0
        if proc.returncode != 0:
            raise SystemExit(f"run failed: {proc.stderr.strip()[-500:]}")
        s = json.loads(out.read_text())
    if s["windows_skipped"] or s["samples_received"] != round(duration * 500):
        raise SystemExit(f"run lost data: {s['windows_skipped']} windows skipped, "
                         f"{s['samples_received']} samples received")
    return {"data_s": duration, "wall_s": wall, "speed_x": duration / wall, "cpu_s": cpu,
            "fit_cpu_s": s["fit_cpu_s"], "in_run_s": s["wall_time_s"],
            "windows": s["windows_fitted"], "gfrf_analysed": s["gfrf"]["models_analysed"],
            "load_avg_1min": load}


def _line(r: dict[str, Any]) -> str:
    return (f"{r['data_s']:g} s of data in {r['wall_s']:.2f} s wall = {r['speed_x']:.1f}x real "
            f"time; CPU {r['cpu_s']:.2f} s (fits {r['fit_cpu_s']:.2f} s), {r['windows']} "
            f"windows, {r['gfrf_analysed']} GFRF analyses; load average "
            f"{r['load_avg_1min']:.2f} on {os.cpu_count()} cores")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=60.0, help="seconds of data (default 60)")
    p.add_argument("--repeat", type=int, default=3, help="runs (default 3; the best counts)")
    p.add_argument("--baseline", type=Path,
                   help="another checkout: alternate its runs with this one's, compare medians")
    p.add_argument("--json", help="write the results as JSON")
    args = p.parse_args()
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_LOG_DIR": tempfile.mkdtemp(prefix="sim_clock_bench_log_")}
    env.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 90))  # below the tests' range
    envs = {"this": env}
    if args.baseline is not None:
        if not (args.baseline / "pmsm_sysid" / "__init__.py").is_file():
            raise SystemExit(f"--baseline {args.baseline}: no pmsm_sysid package there")
        envs = {"baseline": {**env, "PYTHONPATH": str(args.baseline.resolve())}, "this": env}
    runs: dict[str, list[dict[str, Any]]] = {k: [] for k in envs}
    for i in range(args.repeat):
        for name, e in envs.items():
            r = one_run(args.duration, e)
            runs[name].append(r)
            print(f"run {i + 1} ({name}): {_line(r)}", flush=True)
    best = max(runs["this"], key=lambda r: r["speed_x"])
    verdict = "meets" if best["speed_x"] >= TARGET else "is below"
    print(f"best: {best['speed_x']:.1f}x real time (real time = 1.0x: {args.duration:g} s of "
          f"data take {args.duration:g} s); {verdict} the {TARGET:g}x target "
          f"(load average {best['load_avg_1min']:.2f}: the target is for an idle machine)")
    for name, rs in runs.items():
        print(f"median ({name}, {len(rs)} runs): "
              f"{statistics.median(r['speed_x'] for r in rs):.1f}x real time, CPU "
              f"{statistics.median(r['cpu_s'] for r in rs):.2f} s")
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": runs, "best": best}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
