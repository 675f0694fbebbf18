"""Live benchmark of the online pipeline: real time at 500 Hz, then a 5 kHz input.

Phase 1 — ``run`` as shipped, in one process: simulated motor (wall clock, 500 Hz, the noisy
nominal plant and the paper's speed excitation), identifier (speed and position models,
window 1000, hop 250) and GFRF node for ``--duration`` seconds (default 60). Reported:
samples published/received/dropped/missing, windows fitted/skipped, fit latency p50/p99
(window due -> result ready), CPU per node and per thread, resident memory over time.

Phase 2 — the same identification side fed at 5 kHz by a motor process of its own
(``run --nodes sim`` with the plant's sample rate at 5000 Hz) for ``--fast-duration``
seconds: windows are due ten times as often as fits finish, so the latest-wins queue skips
windows; the counts and the memory trace show it degrading gracefully.

CPU per node: the executor thread runs every node's callbacks; each subscription and timer
callback is wrapped here to add its thread CPU time to its node. The fitting threads (the
identifier's and the GFRF node's) report their own CPU. "middleware" is the rest of the
process (DDS threads). Usage: ``python bench/live_bench.py [--duration S] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
NAMESPACE = f"/bench{os.getpid()}"  # input topics of its own: no cross-talk on a shared host


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def instrument(nodes: dict[str, Any], cpu: dict[str, float]) -> None:
    """Wrap every subscription and timer callback to add its thread CPU time to its node."""

    def wrap(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any) -> Any:
            t0 = time.thread_time()
            try:
                return fn(*args)
            finally:
                cpu[name] += time.thread_time() - t0
        return timed

    for name, node in nodes.items():
        for entity in [*node.subscriptions, *node.timers]:
            entity.callback = wrap(name, entity.callback)


def _memory_trend(trace: list[tuple[float, float]]) -> dict[str, float]:
    """RSS at start/end, max, and the slope over the second half (MB per minute)."""
    import numpy as np

    t = np.array([p[0] for p in trace])
    m = np.array([p[1] for p in trace])
    half = t >= t[-1] / 2
    slope = float(np.polyfit(t[half], m[half], 1)[0] * 60) if half.sum() > 2 else float("nan")
    return {"rss_start_mb": float(m[0]), "rss_end_mb": float(m[-1]), "rss_max_mb": float(m.max()),
            "rss_slope_second_half_mb_per_min": slope}


def _spin(pipe: Any, done: Callable[[], bool], trace: list[tuple[float, float]]) -> None:
    t0 = time.monotonic()
    next_sample = t0
    while not done():
        pipe.executor.spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if now >= next_sample:
            trace.append((now - t0, rss_mb()))
            next_sample = now + 1.0


def _report(pipe: Any, cpu: dict[str, float], main_cpu: float, proc_cpu: float,
            wall: float, trace: list[tuple[float, float]]) -> dict[str, Any]:
    s = pipe.summary()
    ident, gfrf = pipe.identifier, pipe.gfrf
    fit_cpu = ident.engine.stats.fit_cpu_s
    gfrf_cpu = gfrf.worker.stats.cpu_s if gfrf is not None else 0.0
    per_node = {name: cpu[name] for name in pipe.nodes if name in cpu}
    per_node["identifier (fit thread)"] = fit_cpu
    if gfrf is not None:
        per_node["gfrf (analysis thread)"] = gfrf_cpu
    per_node["executor (other)"] = max(main_cpu - sum(cpu.values()), 0.0)
    per_node["middleware + other threads"] = max(proc_cpu - main_cpu - fit_cpu - gfrf_cpu, 0.0)
    keys = ("samples_published", "samples_received", "samples_dropped", "samples_missing",
            "unaligned", "windows_due", "windows_fitted", "windows_skipped", "windows_failed",
            "fit_latency_p50_ms", "fit_latency_p99_ms")
    out = {k: s.get(k) for k in keys}
    out.update({"wall_s": wall, "cpu_percent_of_one_core": {k: 100 * v / wall
                                                            for k, v in per_node.items()},
                "gfrf": s.get("gfrf"), "errors": s.get("errors"), **_memory_trend(trace)})
    return out


def phase_realtime(duration: float, method: str) -> dict[str, Any]:
    from pmsm_sysid.app import build_pipeline
    from pmsm_sysid.core.plant import load_plant

    cpu: dict[str, float] = defaultdict(float)
    trace: list[tuple[float, float]] = []
    with build_pipeline(plant=load_plant(REPO / "plants" / "nominal_noisy.yaml"),
                        namespace=NAMESPACE, identifier_params={"method": method}) as pipe:
        instrument(pipe.nodes, cpu)
        limit = round(duration * pipe.sim.fs)
        pipe.sim.set_parameters([_param("max_samples", limit)])
        t0, c0, p0 = time.monotonic(), time.thread_time(), time.process_time()
        _spin(pipe, lambda: pipe.sim.published >= limit, trace)
        wall, main_cpu = time.monotonic() - t0, time.thread_time() - c0
        proc_cpu = time.process_time() - p0
        pipe.finish()
        return _report(pipe, cpu, main_cpu, proc_cpu, wall, trace)


def _param(name: str, value: Any) -> Any:
    from rclpy.parameter import Parameter

    return Parameter(name, value=value)


def phase_fast(duration: float, method: str, rate_hz: float) -> dict[str, Any]:
    import yaml

    from pmsm_sysid.app import build_pipeline

    plant = yaml.safe_load((REPO / "plants" / "nominal_noisy.yaml").read_text())
    plant["sample_rate_hz"] = rate_hz
    cpu: dict[str, float] = defaultdict(float)
    trace: list[tuple[float, float]] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plant.yaml"
        path.write_text(yaml.safe_dump(plant))
        with build_pipeline(["identifier", "gfrf"], namespace=NAMESPACE,
                            identifier_params={"method": method}) as pipe:
            instrument(pipe.nodes, cpu)
            sim = subprocess.Popen([sys.executable, "-m", "pmsm_sysid.cli", "run", "--nodes",
                                    "sim", "--plant", str(path), "--duration", str(duration),
                                    "--namespace", NAMESPACE,
                                    "--json", str(Path(tmp) / "sim.json")],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            t0, c0, p0 = time.monotonic(), time.thread_time(), time.process_time()
            _spin(pipe, lambda: sim.poll() is not None, trace)
            end = time.monotonic() + 2.0  # what is still in flight
            _spin(pipe, lambda: time.monotonic() > end, trace)
            wall, main_cpu = time.monotonic() - t0, time.thread_time() - c0
            proc_cpu = time.process_time() - p0
            pipe.finish()
            out = _report(pipe, cpu, main_cpu, proc_cpu, wall, trace)
            sim_summary = json.loads((Path(tmp) / "sim.json").read_text())
            out["samples_published"] = sim_summary["samples_published"]
            out["input_rate_hz"] = rate_hz
            return out


def _row(label: str, value: Any) -> str:
    if isinstance(value, float):
        value = f"{value:.1f}"
    return f"  {label:<40} {value}"


def print_table(title: str, r: dict[str, Any]) -> None:
    print(f"\n{title}")
    for key in ("samples_published", "samples_received", "samples_dropped", "samples_missing",
                "windows_due", "windows_fitted", "windows_skipped", "fit_latency_p50_ms",
                "fit_latency_p99_ms", "rss_start_mb", "rss_end_mb", "rss_max_mb",
                "rss_slope_second_half_mb_per_min", "wall_s"):
        print(_row(key, r.get(key)))
    print("  CPU (% of one core):")
    for k, v in r["cpu_percent_of_one_core"].items():
        print(_row("  " + k, v))
    if r.get("gfrf"):
        g = r["gfrf"]
        print(_row("gfrf models analysed / skipped",
                   f"{g['models_analysed']} / {g['models_skipped']}"))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=60.0, help="phase 1 seconds (default 60)")
    p.add_argument("--fast-duration", type=float, default=None,
                   help="phase 2 seconds (default: half of --duration)")
    p.add_argument("--fast-rate", type=float, default=5000.0, help="phase 2 input rate (Hz)")
    p.add_argument("--method", choices=("iofr", "ofr"), default=None,
                   help="term selection (default: the identifier node's, ofr)")
    p.add_argument("--skip-fast", action="store_true", help="run phase 1 only")
    p.add_argument("--json", help="write the results as JSON")
    args = p.parse_args()
    # a domain below the test suite's range (100..), different per run
    os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 90))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="live_bench_log_"))
    if args.method is None:
        from pmsm_sysid.nodes.identifier_node import DEFAULTS

        args.method = DEFAULTS["method"]
    results = {"method": args.method, "cpu_count": os.cpu_count(),
               "load_avg_at_start": os.getloadavg()}
    results["realtime_500hz"] = phase_realtime(args.duration, args.method)
    print_table(f"real time, 500 Hz, {args.duration:g} s, method {args.method}",
                results["realtime_500hz"])
    if not args.skip_fast:
        d = args.fast_duration or args.duration / 2
        results["fast"] = phase_fast(d, args.method, args.fast_rate)
        print_table(f"input at {args.fast_rate:g} Hz from another process, {d:g} s",
                    results["fast"])
    results["load_avg_at_end"] = os.getloadavg()
    print(f"\nload average start {results['load_avg_at_start']}, "
          f"end {results['load_avg_at_end']} ({os.cpu_count()} cores)")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
