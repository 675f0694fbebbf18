"""Soak and overload of the real-time pipeline.

1. **Soak**: ``pmsm-sysid run`` (simulated motor + identifier + GFRF in one process, wall
   clock, 500 Hz) for ``--minutes`` (default 10). The process's resident memory is sampled
   every ``--interval`` seconds from /proc; its slope after a warm-up (least squares, MB per
   minute) says whether memory is flat. The run's own summary gives samples published and
   received, dropped and missing samples, windows fitted/skipped and fit latency.
2. **Overload through ROS**: the motor at ``--factor`` (default 10) x real time in one
   process (``run --nodes sim --clock sim --rate F``) and the identifier in another
   (``run --nodes identifier``) for ``--load-minutes``. Whatever the subscriber cannot take
   is lost in transport (keep-last queues) and counted as missing, never invented; memory
   must stay flat.
3. **Overload of the engine**: the identifier's own data path (aligner, window ring,
   latest-wins queue of size 1, fitting thread with the node's default fits) fed the
   simulated motor's samples at ``--factor`` x 500 Hz in this process: it cannot fit every
   window, so the queue skips the oldest and counts it; no sample is dropped, the queue
   stays bounded and memory flat.

The machine is shared (2 cores, other work running), so latencies and the achieved overload
rate are noisy; counts of samples and memory are not.

    .venv/bin/python bench/soak_bench.py [--minutes 10] [--load-minutes 2] [--factor 10]
                                         [--interval 5] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

EXE = [sys.executable, "-m", "pmsm_sysid.cli"]


def rss_mb(pid: int) -> float | None:
    """Resident set size of a process in MB (None once it has exited)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def slope_mb_per_min(series: list[tuple[float, float]], warmup_s: float) -> float | None:
    """Least-squares slope of RSS over time after the warm-up (MB per minute)."""
    pts = [(t, m) for t, m in series if t >= warmup_s]
    if len(pts) < 3:
        return None
    t, m = np.array(pts).T
    return float(np.polyfit(t / 60.0, m, 1)[0])


def env() -> dict[str, str]:
    # 231: outside the domains the test suite hands out (100..229), so a benchmark and a
    # test run on one host do not hear each other
    domain = os.environ.get("SOAK_DOMAIN_ID") or "231"
    log_dir = tempfile.mkdtemp(prefix="soak_ros_log_")
    return dict(os.environ, ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                ROS_LOG_DIR=log_dir, PYTHONUNBUFFERED="1")


def watch(proc: subprocess.Popen[bytes], interval: float,
          limit_s: float) -> list[tuple[float, float]]:
    """Sample the RSS of ``proc`` until it exits (or ``limit_s`` passes: then SIGTERM)."""
    t0 = time.monotonic()
    series: list[tuple[float, float]] = []
    while proc.poll() is None:
        now = time.monotonic() - t0
        mb = rss_mb(proc.pid)
        if mb is not None:
            series.append((now, mb))
        if now > limit_s:
            proc.terminate()
        time.sleep(interval)
    return series


def run_json(args: list[str], out: Path, e: dict[str, str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen([*EXE, "run", *args, "--json", str(out)], env=e,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def soak(minutes: float, interval: float, tmp: Path) -> dict[str, Any]:
    seconds = 60.0 * minutes
    proc = run_json(["--duration", f"{seconds:g}"], tmp / "soak.json", env())
    series = watch(proc, interval, seconds + 120)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"soak run failed ({proc.returncode}): {err[-2000:]}")
    s = json.loads((tmp / "soak.json").read_text())
    return {"phase": "soak", "rate_hz": 500.0, "seconds": seconds, "summary": s,
            "rss": series, "warmup_s": min(60.0, seconds / 5)}


def overload(minutes: float, factor: float, interval: float, tmp: Path) -> dict[str, Any]:
    seconds = 60.0 * minutes
    e = env()
    ident = run_json(["--nodes", "identifier", "--duration", f"{seconds + 15:g}"],
                     tmp / "ident.json", e)
    time.sleep(5.0)  # subscriptions up before the motor starts
    # --duration counts simulated seconds when the sim node is in the process
    sim = run_json(["--nodes", "sim", "--clock", "sim", "--rate", f"{factor:g}",
                    "--duration", f"{seconds * factor:g}"], tmp / "sim.json", e)
    t_sim = time.monotonic()
    series = watch(ident, interval, seconds + 180)
    try:
        sim.wait(60)
    except subprocess.TimeoutExpired:
        sim.terminate()
        sim.wait(30)
    sim_wall = time.monotonic() - t_sim
    for p, name in ((ident, "identifier"), (sim, "sim")):
        if p.returncode != 0:
            err = p.stderr.read().decode() if p.stderr else ""
            raise SystemExit(f"overload {name} failed ({p.returncode}): {err[-2000:]}")
    s = json.loads((tmp / "ident.json").read_text())
    published = json.loads((tmp / "sim.json").read_text())["samples_published"]
    s["samples_published"] = published
    return {"phase": f"overload x{factor:g}", "rate_hz": 500.0 * factor,
            "achieved_rate_hz": published / min(seconds, sim_wall), "seconds": seconds,
            "summary": s,
            "rss": series, "warmup_s": min(30.0, seconds / 4)}


def engine_overload(minutes: float, factor: float, interval: float) -> dict[str, Any]:
    """The identifier's data path without ROS transport: the simulated motor's samples
    pushed into its engine (aligner, window ring, latest-wins queue, fitting thread with the
    node's default fits) at ``factor`` x 500 Hz, paced in 10 ms blocks."""
    import threading

    from pmsm_sysid.core.online.engine import EngineConfig, OnlineEngine
    from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config
    from pmsm_sysid.core.physics.excitation import make_excitation
    from pmsm_sysid.core.physics.motor import simulate
    from pmsm_sysid.core.physics.plant import nominal_plant
    from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS as DEFAULTS

    fs, seconds = 500.0, 60.0 * minutes
    rec = simulate(nominal_plant(), make_excitation("paper-speed", 30000, fs), seed=1)
    values = np.stack([rec.thrust, rec.speed, rec.position], axis=1).tolist()
    tracker = WindowTracker(tracker_config(DEFAULTS))
    engine: OnlineEngine[Any] = OnlineEngine(
        EngineConfig(window=int(DEFAULTS["window"]), hop=int(DEFAULTS["hop"]),
                     history=tracker.history, queue_size=int(DEFAULTS["queue_size"])),
        tracker.process)
    engine.start()
    series: list[tuple[float, float]] = []
    done = threading.Event()
    t0 = time.monotonic()

    def sample_rss() -> None:
        while not done.wait(interval):
            mb = rss_mb(os.getpid())
            if mb is not None:
                series.append((time.monotonic() - t0, mb))

    watcher = threading.Thread(target=sample_rss, daemon=True)
    watcher.start()
    k, per_block, max_pending = 0, int(fs * factor / 100), 0
    while time.monotonic() - t0 < seconds:
        for _ in range(per_block):
            engine.push_sample(k * round(1e9 / fs), values[k % len(values)])
            k += 1
        max_pending = max(max_pending, engine.stats.windows_pending)
        delay = t0 + k / (fs * factor) - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    engine.wait_idle(120)
    engine.stop()
    done.set()
    watcher.join()
    s = engine.stats.to_dict()
    s.update(samples_published=k, max_windows_pending=max_pending)
    return {"phase": f"engine x{factor:g}", "rate_hz": fs * factor,
            "achieved_rate_hz": k / (time.monotonic() - t0), "seconds": seconds,
            "summary": s, "rss": series, "warmup_s": min(30.0, seconds / 4)}


def row(r: dict[str, Any]) -> list[str]:
    s, rss = r["summary"], [m for _, m in r["rss"]]
    slope = slope_mb_per_min(r["rss"], r["warmup_s"])
    lat = "/".join("-" if s.get(k) is None else f"{s[k]:.0f}"
                   for k in ("fit_latency_p50_ms", "fit_latency_p99_ms"))
    rate = f"{r.get('achieved_rate_hz', r['rate_hz']):.0f}"
    return [r["phase"], rate, f"{r['seconds']:.0f}", str(s["samples_published"]),
            str(s["samples_received"]), str(s["samples_dropped"]), str(s["samples_missing"]),
            str(s["windows_fitted"]), str(s["windows_skipped"]), str(s["windows_failed"]), lat,
            f"{rss[0]:.0f}/{rss[-1]:.0f}/{max(rss):.0f}" if rss else "-",
            "-" if slope is None else f"{slope:+.2f}"]


HEAD = ["phase", "Hz", "s", "published", "received", "dropped", "missing", "fitted",
        "skipped", "failed", "fit p50/p99 ms", "RSS first/last/max MB", "MB/min"]


def table(rows: list[list[str]]) -> str:
    widths = [max(len(x) for x in col) for col in zip(HEAD, *rows, strict=True)]
    lines = ["  ".join(x.rjust(w) for x, w in zip(r, widths, strict=True)) for r in [HEAD, *rows]]
    return "\n".join([lines[0], "  ".join("-" * w for w in widths), *lines[1:]])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="soak length (default 10)")
    ap.add_argument("--load-minutes", type=float, default=2.0,
                    help="overload length (default 2; 0 skips it)")
    ap.add_argument("--factor", type=float, default=10.0, help="overload rate factor")
    ap.add_argument("--interval", type=float, default=5.0, help="RSS sampling period (s)")
    ap.add_argument("--json", metavar="FILE", help="write every result and RSS series")
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory(prefix="soak_") as d:
        tmp = Path(d)
        if args.minutes > 0:
            results.append(soak(args.minutes, args.interval, tmp))
        if args.load_minutes > 0:
            results.append(overload(args.load_minutes, args.factor, args.interval, tmp))
            results.append(engine_overload(args.load_minutes, args.factor, args.interval))
    print(table([row(r) for r in results]))
    for r in results:
        s = r["summary"]
        print(f"{r['phase']}: windows due {s.get('windows_due')}, most pending "
              f"{s.get('max_windows_pending', '-')}, unaligned {s.get('unaligned')}, "
              f"out of order {s.get('out_of_order')}, errors {len(s.get('errors') or [])}")
    if args.json:
        slim = [{**r, "summary": {k: v for k, v in r["summary"].items()
                                  if not k.startswith("last_")}} for r in results]
        Path(args.json).write_text(json.dumps(slim, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
