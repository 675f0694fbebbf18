"""Kill benchmark: how close to a SIGKILL does the recording of ``run --record`` reach?

For each cell the benchmark starts the CPU hogs itself (busy Python loops, one core each),
starts ``pmsm-sysid run --duration 120 --record BAG`` (wall clock, 500 Hz, the default plant,
excitation and nodes), waits until the run says it is running plus ``--after`` seconds, sends
SIGKILL to the run process (no clean-up can run there), waits until every process the run had
started has ended (the recorder finalises the bag when it sees its owner gone), stops the
hogs and reads the bag with a stock ``rosbags`` reader:

* **last sample before the kill**: the kill time minus the header stamp of the last complete
  sample (the newest stamp present on all three input topics) -- the figure a crash costs;
* **last receive before the kill**: the same for the bag time (when the recorder received
  the last input message), i.e. the part the recorder and the middleware add;
* samples in the bag, and the stamp gaps inside it (samples lost on the way, not at the end);
* how long the recorder took to finalise the bag after the kill.

The machine's load average is printed with every cell. Usage: ``python bench/kill_bench.py
[--repeat 3] [--after 15] [--hogs 0,1] [--json FILE] [--markdown]``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CLI = [sys.executable, "-m", "pmsm_sysid.cli", "run"]
INPUTS = ("thrust", "speed", "position")
PERIOD_NS = 2_000_000  # 500 Hz


def start_hogs(n: int) -> list[subprocess.Popen[bytes]]:
    """``n`` CPU-bound processes (one core each)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def stop_hogs(hogs: list[subprocess.Popen[bytes]]) -> None:
    for h in hogs:
        h.terminate()
    for h in hogs:
        h.wait(10)


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii") as f:
                parent = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        if parent == pid:
            out.append(int(entry))
    return out


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (its recorder, fit workers, forkserver, ...)."""
    found, todo = [], [pid]
    while todo:
        kids = _children(todo.pop())
        found += kids
        todo += kids
    return found


def wait_gone(pids: list[int], timeout_s: float) -> list[int]:
    """Wait until ``pids`` have ended; those still running after ``timeout_s``."""
    from pmsm_sysid.core.online.workerproc import owner_alive

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        left = [p for p in pids if owner_alive(p)]
        if not left:
            return []
        time.sleep(0.02)
    return [p for p in pids if owner_alive(p)]


def read_inputs(bag: Path) -> dict[str, Any]:
    """Per input topic: header stamps and the newest bag (receive) time."""
    from rosbags.highlevel import AnyReader

    stamps: dict[str, list[int]] = {s: [] for s in INPUTS}
    received: dict[str, int] = {}
    with AnyReader([bag]) as reader:
        for conn, t, raw in reader.messages():
            sig = conn.topic.rsplit("/", 1)[-1]
            if conn.topic == f"/pmsm/{sig}" and sig in stamps:
                msg = reader.deserialize(raw, conn.msgtype)
                stamps[sig].append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
                received[sig] = max(received.get(sig, 0), t)
    return {"stamps": stamps, "received": received}


def run_cell(hogs: int, after_s: float, env: dict[str, str]) -> dict[str, Any]:
    """One ``run --record`` killed ``after_s`` seconds after it started running."""
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bag"
        procs = start_hogs(hogs)
        load0 = os.getloadavg()[0]
        try:
            run = subprocess.Popen([*CLI, "--duration", "120", "--record", str(bag)], env=env,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            assert run.stderr is not None
            line = run.stderr.readline()  # "pmsm-sysid run: running ..." once it publishes
            if "running" not in line:
                run.kill()
                return {"hogs": hogs, "error": line.strip() or run.stderr.read()[-300:]}
            time.sleep(after_s)
            below = descendants(run.pid)
            kill_ns = time.time_ns()
            os.kill(run.pid, signal.SIGKILL)
            t_kill = time.monotonic()
            run.wait()
            left = wait_gone(below, 120.0)
            finalised_s = time.monotonic() - t_kill
            for pid in left:  # not expected: say so, and leave nothing behind
                os.kill(pid, signal.SIGKILL)
        finally:
            stop_hogs(procs)
        content = read_inputs(bag)
    stamps, received = content["stamps"], content["received"]
    last_complete = min(max(ts) for ts in stamps.values())
    gaps = sum(max(0, (b - a) // PERIOD_NS - 1)
               for ts in stamps.values() for a, b in itertools.pairwise(sorted(ts)))
    return {
        "hogs": hogs, "load_avg_1min": load0, "after_s": after_s,
        "last_sample_before_kill_ms": (kill_ns - last_complete) / 1e6,
        "last_receive_before_kill_ms": (kill_ns - max(received.values())) / 1e6,
        "bag_samples": min(len(ts) for ts in stamps.values()),
        "samples_missing_inside": gaps,
        "finalised_after_kill_s": finalised_s, "left_running": len(left),
    }


COLUMNS = (("CPU hogs", "hogs"), ("load (1 min)", "load_avg_1min"),
           ("last sample before kill ms", "last_sample_before_kill_ms"),
           ("last receive before kill ms", "last_receive_before_kill_ms"),
           ("bag samples/topic", "bag_samples"), ("missing inside", "samples_missing_inside"),
           ("bag final after kill s", "finalised_after_kill_s"))


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.0f}" if abs(v) >= 10 else f"{v:.1f}"
    return "-" if v is None else str(v)


def print_table(rows: list[dict[str, Any]], markdown: bool) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="run --duration 120 --record, SIGKILL of the run process")
    for title, _ in COLUMNS:
        table.add_column(title, justify="right")
    for r in rows:
        table.add_row(*(_cell(r.get(k)) if "error" not in r else r["error"][:40]
                        for _, k in COLUMNS))
    Console(width=max(Console().width, 150)).print(table)
    if markdown:
        print("| " + " | ".join(t for t, _ in COLUMNS) + " |")
        print("|" + "---:|" * len(COLUMNS))
        for r in rows:
            print("| " + " | ".join(_cell(r.get(k)) for _, k in COLUMNS) + " |")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=3, help="kills per cell (3)")
    p.add_argument("--after", type=float, default=15.0,
                   help="seconds of running before the kill (15)")
    p.add_argument("--hogs", default="0,1", help="CPU hog counts to run beside (0,1)")
    p.add_argument("--json", help="write the results as JSON")
    p.add_argument("--markdown", action="store_true", help="also print a markdown table")
    args = p.parse_args()
    env = {**os.environ, "PYTHONPATH": str(REPO), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_LOG_DIR": tempfile.mkdtemp(prefix="kill_bench_log_")}
    env.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 90))
    rows = []
    for hogs in [int(h) for h in args.hogs.split(",")]:
        for _ in range(args.repeat):
            rows.append(run_cell(hogs, args.after, env))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    print_table(rows, args.markdown)
    worst = {h: max((r["last_sample_before_kill_ms"] for r in rows
                     if r["hogs"] == h and "error" not in r), default=None)
             for h in sorted({r["hogs"] for r in rows})}
    print("worst last sample before the kill: " + ", ".join(
        f"{h} hog(s) {_cell(w)} ms" for h, w in worst.items()))
    if args.json:
        Path(args.json).write_text(json.dumps({"cpu_count": os.cpu_count(), "cells": rows},
                                              indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
