"""Fleet benchmark: many simulated recordings analysed one after the other in a plain loop,
then by ``ps.fleet`` on a local Dask cluster of 1 worker, then of 2 workers, in one run.

The recordings: ``--recordings`` (default 200) of ``--duration`` s (default 10) over 4 axes,
each a drive (the packaged drive plant with 5 N of Coulomb friction) under the APRBS test
motion, each axis at its own mass. Each is analysed as ``pmsm-sysid fleet`` analyses it
(:func:`pmsm_sysid.api.fleet_row.recording_row`: the fitted plant and the diagnosis of the
nominal plant).

Printed: recordings per minute of each; the speed-up of 2 workers over 1; Dask's overhead,
the time of 1 worker (cluster start, reading the recordings for their content keys,
scheduling, collecting the rows) over the plain loop's, minus one; the peak resident memory
of each worker process; and the CPU time each run used (this process -- the loop, or the
Dask client, scheduler and nannies -- plus the workers), whose ratio is Dask's overhead in
work whatever else runs on the machine. The machine is shared (2 cores, other work
running): the load average before and after is printed with the figures, and whether the
kernel groups processes by session for CPU time (autogroup): then the workers of one
session share that session's part of the machine, and a second worker only speeds a batch
up as far as the other sessions leave CPU idle.

    .venv/bin/python bench/fleet_bench.py [--recordings 200] [--duration 10] [--json FILE]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy: one BLAS thread per process

REPO = Path(__file__).resolve().parents[1]
AXES = ("/axis1", "/axis2", "/axis3", "/axis4")
EPOCH = 1_767_571_200.0


def make_recordings(root: Path, n: int, duration: float) -> float:
    """``n`` recordings over the four axes; returns the seconds it took."""
    import pmsm_sysid as ps
    from pmsm_sysid.core.physics.plant import CoulombFriction

    start = time.perf_counter()
    base = dataclasses.replace(ps.Plant.from_yaml(REPO / "pmsm_sysid" / "data" / "drive.yaml"),
                               coulomb_friction=CoulombFriction(5.0))
    for i in range(n):
        axis = AXES[i % len(AXES)]
        plant = dataclasses.replace(base, mass_kg=base.mass_kg * (1 + 0.05 * (i % len(AXES))))
        rec = ps.simulate(plant, excitation="aprbs", duration=duration, seed=i)
        rec = dataclasses.replace(rec, t=rec.t + EPOCH + 86400.0 * (i // len(AXES)))
        ps.write_bag(rec, root / f"{axis.strip('/')}_{i:04d}", namespace=axis)
    return time.perf_counter() - start


def _cpu_s() -> float:
    """CPU time of this process so far (user + system, s)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def plain_loop(root: Path) -> tuple[float, int, float]:
    """Every recording's row, one after the other in this process: (seconds, rows ok, CPU
    seconds)."""
    from pmsm_sysid.api.fleet_row import recording_row
    from pmsm_sysid.batch.inputs import all_units, expand
    from pmsm_sysid.core.physics.plant import load_plant

    plant = load_plant(REPO / "plants" / "nominal.yaml")
    start, cpu = time.perf_counter(), _cpu_s()
    units = list(all_units(expand([str(root)])))
    rows = [recording_row(u.path, plant, namespace=u.namespace, joint=u.joint, axis=u.axis,
                          content_sha256=u.content) for u in units]
    return (time.perf_counter() - start, sum(r["status"] == "ok" for r in rows),
            _cpu_s() - cpu)


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def on_dask(root: Path, workers: int) -> dict[str, Any]:
    """``ps.fleet`` on a fresh local cluster made as the command makes it
    (:func:`pmsm_sysid.batch.cluster.local_cluster`), timed from the cluster's start."""
    import pmsm_sysid as ps
    from pmsm_sysid.batch.cluster import local_cluster

    start, cpu = time.perf_counter(), _cpu_s()
    with local_cluster(workers) as client:
        result = ps.fleet(str(root), plant=REPO / "plants" / "nominal.yaml", client=client)
        seconds = time.perf_counter() - start
        peaks = sorted(client.run(_peak_rss_mb).values())
        worker_cpu = sum(client.run(_cpu_s).values())
    ok = sum(s == "ok" for s in result.table.column("status").to_pylist())
    return {"seconds": seconds, "ok": ok, "peak_rss_mb": peaks,
            "cpu_s": {"client": _cpu_s() - cpu, "workers": worker_cpu}}


def _autogroup() -> bool:
    try:
        return Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1"
    except OSError:
        return False


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recordings", type=int, default=200)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args()
    load = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="fleet-bench-") as tmp:
        root = Path(tmp) / "recordings"
        root.mkdir()
        made = make_recordings(root, args.recordings, args.duration)
        print(f"{args.recordings} recordings of {args.duration:g} s over {len(AXES)} axes "
              f"written in {made:.0f} s")
        loop_s, loop_ok, loop_cpu = plain_loop(root)
        one = on_dask(root, 1)
        two = on_dask(root, 2)
    load.append(os.getloadavg()[0])
    n = args.recordings
    out = {
        "recordings": n, "duration_s": args.duration, "load_average": load,
        "autogroup": _autogroup(),
        "loop": {"seconds": loop_s, "ok": loop_ok, "per_minute": 60 * n / loop_s,
                 "cpu_s": loop_cpu},
        "one_worker": {**one, "per_minute": 60 * n / one["seconds"]},
        "two_workers": {**two, "per_minute": 60 * n / two["seconds"]},
        "speed_up": one["seconds"] / two["seconds"],
        "overhead": one["seconds"] / loop_s - 1.0,
        "cpu_overhead": sum(one["cpu_s"].values()) / loop_cpu - 1.0,
    }
    print(f"plain loop, one process: {loop_s:8.1f} s  {out['loop']['per_minute']:6.1f} "
          f"recordings/min  ({loop_ok} ok; CPU {loop_cpu:.0f} s)")
    for key, label in (("one_worker", "Dask, 1 worker:"), ("two_workers", "Dask, 2 workers:")):
        r = out[key]
        print(f"{label:24s} {r['seconds']:8.1f} s  {r['per_minute']:6.1f} recordings/min  "
              f"({r['ok']} ok; CPU {r['cpu_s']['workers']:.0f} s in the workers, "
              f"{r['cpu_s']['client']:.0f} s here; peak memory per worker "
              + ", ".join(f"{m:.0f} MB" for m in r["peak_rss_mb"]) + ")")
    print(f"speed-up 2 workers / 1 worker: {out['speed_up']:.2f}x (target >= 1.7x)")
    print(f"Dask overhead, 1 worker against the plain loop: {100 * out['overhead']:+.1f} % "
          f"(target <= 10 %)")
    print(f"Dask overhead in CPU time, 1 worker against the plain loop: "
          f"{100 * out['cpu_overhead']:+.1f} %")
    print(f"load average (1 min) before {load[0]:.1f}, after {load[1]:.1f} (2 cores); CPU "
          f"time shared by session (autogroup): {'yes' if out['autogroup'] else 'no'}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
