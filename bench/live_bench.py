"""Live benchmark: ``run --record`` at hop 250/100/50, idle and beside 1 and 2 CPU hogs.

For each cell the benchmark starts the CPU hogs itself (busy Python loops, one core each),
runs ``pmsm-sysid run --record BAG --duration D --hop H --json S`` (wall clock, 500 Hz, the
default plant and excitation, speed and position models, GFRF node), stops the hogs and
reports: windows due/skipped, fit latency p50/p99 (from the moment a window is due to the
moment its result is ready), the samples the recorder lost by the summary, and what the bag
itself holds (samples per input topic, read back with a stock ``rosbags`` reader; stamps
checked unbroken), so the summary is checked against the bag. Then, unless ``--no-sim``,
the wall time of ``run --clock sim --duration 60`` (as fast as identification allows).

The machine's load average is printed with every cell: other work on the machine counts as
load the cell ran beside. Usage: ``python bench/live_bench.py [--duration 30]
[--hops 250,100,50] [--hogs 0,1,2] [--json FILE] [--markdown]``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "pmsm_sysid.cli", "run"]
INPUTS = ("thrust", "speed", "position")


def start_hogs(n: int) -> list[subprocess.Popen[bytes]]:
    """``n`` CPU-bound processes (one core each)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def stop_hogs(hogs: list[subprocess.Popen[bytes]]) -> None:
    for h in hogs:
        h.terminate()
    for h in hogs:
        h.wait(10)


def read_bag(bag: Path, namespace: str = "/pmsm") -> dict[str, Any]:
    """Samples per input topic in the bag and whether their stamps are unbroken."""
    from rosbags.highlevel import AnyReader

    stamps: dict[str, list[int]] = {s: [] for s in INPUTS}
    total = 0
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            total += 1
            sig = conn.topic.rsplit("/", 1)[-1]
            if conn.topic == f"{namespace}/{sig}" and sig in stamps:
                msg = reader.deserialize(raw, conn.msgtype)
                stamps[sig].append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    steps = {b - a for ts in stamps.values() for a, b in itertools.pairwise(ts)}
    return {"messages": total, "samples": {s: len(ts) for s, ts in stamps.items()},
            "stamps_unbroken": len(steps) <= 1}


def run_cell(hop: int, hogs: int, duration: float, env: dict[str, str]) -> dict[str, Any]:
    """One ``run --record`` beside ``hogs`` CPU hogs; the summary and the bag's content."""
    with tempfile.TemporaryDirectory() as tmp:
        bag, out = Path(tmp) / "bag", Path(tmp) / "run.json"
        procs = start_hogs(hogs)
        load0 = os.getloadavg()[0]
        try:
            t0 = time.monotonic()
            run = subprocess.run([*CLI, "--record", str(bag), "--duration", str(duration),
                                  "--hop", str(hop), "--json", str(out)],
                                 env=env, capture_output=True, text=True, timeout=30 * duration)
            wall = time.monotonic() - t0
        finally:
            stop_hogs(procs)
        if run.returncode != 0:
            return {"hop": hop, "hogs": hogs, "error": run.stderr.strip()[-500:]}
        s = json.loads(out.read_text())
        content = read_bag(bag)
    in_bag = min(content["samples"].values())
    return {
        "hop": hop, "hogs": hogs, "load_avg_1min": load0, "wall_s": wall,
        "windows_due": s["windows_due"], "windows_skipped": s["windows_skipped"],
        "windows_failed": s["windows_failed"],
        "fit_latency_p50_ms": s["fit_latency_p50_ms"],
        "fit_latency_p99_ms": s["fit_latency_p99_ms"], "fit_cpu_s": s["fit_cpu_s"],
        "samples_published": s["samples_published"], "samples_received": s["samples_received"],
        "record_samples_lost": s["record_samples_lost"], "recorded_messages":
        s["recorded_messages"], "bag_messages": content["messages"], "bag_samples": in_bag,
        "bag_stamps_unbroken": content["stamps_unbroken"],
        "summary_agrees_with_bag": (s["recorded_messages"] == content["messages"]
                                    and s["samples_published"] - in_bag
                                    == s["record_samples_lost"]),
        "gfrf_analysed": s.get("gfrf", {}).get("models_analysed"),
        "gfrf_skipped": s.get("gfrf", {}).get("models_skipped"),
        "headline": run.stdout.strip().splitlines()[-1] if run.stdout.strip() else "",
    }


def run_sim_clock(duration: float, env: dict[str, str]) -> dict[str, Any]:
    """Wall time of ``run --clock sim --duration D`` (idle apart from other users)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        load0 = os.getloadavg()[0]
        t0 = time.monotonic()
        run = subprocess.run([*CLI, "--clock", "sim", "--duration", str(duration),
                              "--json", str(out)], env=env, capture_output=True, text=True,
                             timeout=600)
        wall = time.monotonic() - t0
        if run.returncode != 0:
            return {"error": run.stderr.strip()[-500:]}
        s = json.loads(out.read_text())
    return {"data_s": duration, "wall_s": wall, "load_avg_1min": load0,
            "windows_due": s["windows_due"], "windows_skipped": s["windows_skipped"],
            "samples_received": s["samples_received"], "gfrf": s.get("gfrf")}


COLUMNS = (("hop", "hop"), ("CPU hogs", "hogs"), ("load (1 min)", "load_avg_1min"),
           ("windows due", "windows_due"), ("skipped", "windows_skipped"),
           ("fit p50 ms", "fit_latency_p50_ms"), ("fit p99 ms", "fit_latency_p99_ms"),
           ("recorder lost", "record_samples_lost"), ("bag samples/topic", "bag_samples"),
           ("stamps unbroken", "bag_stamps_unbroken"),
           ("summary = bag", "summary_agrees_with_bag"))


def _cell(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float):
        return f"{v:.0f}" if abs(v) >= 10 else f"{v:.1f}"
    return "-" if v is None else str(v)


def print_rich(rows: list[dict[str, Any]]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="run --record, 500 Hz, wall clock")
    for title, _ in COLUMNS:
        table.add_column(title, justify="right")
    for r in rows:
        table.add_row(*(_cell(r.get(k)) if "error" not in r else r["error"][:40]
                        for _, k in COLUMNS))
    Console(width=max(Console().width, 150)).print(table)


def print_markdown(rows: list[dict[str, Any]]) -> None:
    print("| " + " | ".join(t for t, _ in COLUMNS) + " |")
    print("|" + "---:|" * len(COLUMNS))
    for r in rows:
        print("| " + " | ".join(_cell(r.get(k)) for _, k in COLUMNS) + " |")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=30.0, help="seconds per cell (30)")
    p.add_argument("--hops", default="250,100,50", help="hops to run (250,100,50)")
    p.add_argument("--hogs", default="0,1,2", help="CPU hog counts to run beside (0,1,2)")
    p.add_argument("--no-sim", action="store_true", help="skip the sim-clock run")
    p.add_argument("--json", help="write the results as JSON")
    p.add_argument("--markdown", action="store_true", help="also print a markdown table")
    args = p.parse_args()
    env = {**os.environ, "PYTHONPATH": str(REPO), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_LOG_DIR": tempfile.mkdtemp(prefix="live_bench_log_")}
    env.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 90))  # below the tests' range
    rows = []
    for hop, hogs in itertools.product([int(h) for h in args.hops.split(",")],
                                       [int(h) for h in args.hogs.split(",")]):
        rows.append(run_cell(hop, hogs, args.duration, env))
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    results: dict[str, Any] = {"cpu_count": os.cpu_count(), "duration_s": args.duration,
                               "cells": rows}
    print_rich(rows)
    if args.markdown:
        print_markdown(rows)
    if not args.no_sim:
        results["sim_clock"] = run_sim_clock(60.0, env)
        sc = results["sim_clock"]
        print(f"run --clock sim --duration 60: {_cell(sc.get('wall_s'))} s wall, windows "
              f"skipped {sc.get('windows_skipped')} of {sc.get('windows_due')} (load "
              f"{_cell(sc.get('load_avg_1min'))})")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
