"""Fleet benchmark: many simulated recordings analysed one after the other in a plain loop,
then by ``ps.fleet`` on a local Dask cluster of 1 worker, then of 2 workers, in one run.

The recordings: ``--recordings`` (default 200) of ``--duration`` s (default 10) over 4 axes,
each a drive (the packaged drive plant with 5 N of Coulomb friction) under the APRBS test
motion, each axis at its own mass. Each is analysed as ``pmsm-sysid fleet`` analyses it
(:func:`pmsm_sysid.api.fleet_row.recording_row`: the fitted plant and the diagnosis of the
nominal plant).

Printed: recordings per minute of each; the speed-up of 2 workers over 1; Dask's overhead,
the time of 1 worker (cluster start, reading the recordings for their content keys,
scheduling, collecting the rows) over the plain loop's, minus one; and the peak resident
memory of each worker process. The machine is shared (2 cores, other work running): the
load average before and after is printed with the figures.

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


def plain_loop(root: Path) -> tuple[float, int]:
    """Every recording's row, one after the other in this process: (seconds, rows ok)."""
    from pmsm_sysid.api.fleet_row import recording_row
    from pmsm_sysid.batch.inputs import all_units, expand
    from pmsm_sysid.core.physics.plant import load_plant

    plant = load_plant(REPO / "plants" / "nominal.yaml")
    start = time.perf_counter()
    units = list(all_units(expand([str(root)])))
    rows = [recording_row(u.path, plant, namespace=u.namespace, joint=u.joint, axis=u.axis,
                          content_sha256=u.content) for u in units]
    return time.perf_counter() - start, sum(r["status"] == "ok" for r in rows)


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def on_dask(root: Path, workers: int) -> dict[str, Any]:
    """``ps.fleet`` on a fresh local cluster, timed from the cluster's start."""
    import logging

    from dask.distributed import Client, LocalCluster

    import pmsm_sysid as ps

    start = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        result = ps.fleet(str(root), plant=REPO / "plants" / "nominal.yaml", client=client)
        seconds = time.perf_counter() - start
        peaks = sorted(client.run(_peak_rss_mb).values())
    ok = sum(s == "ok" for s in result.table.column("status").to_pylist())
    return {"seconds": seconds, "ok": ok, "peak_rss_mb": peaks}


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
        loop_s, loop_ok = plain_loop(root)
        one = on_dask(root, 1)
        two = on_dask(root, 2)
    load.append(os.getloadavg()[0])
    n = args.recordings
    out = {
        "recordings": n, "duration_s": args.duration, "load_average": load,
        "loop": {"seconds": loop_s, "ok": loop_ok, "per_minute": 60 * n / loop_s},
        "one_worker": {**one, "per_minute": 60 * n / one["seconds"]},
        "two_workers": {**two, "per_minute": 60 * n / two["seconds"]},
        "speed_up": one["seconds"] / two["seconds"],
        "overhead": one["seconds"] / loop_s - 1.0,
    }
    print(f"plain loop, one process: {loop_s:8.1f} s  {out['loop']['per_minute']:6.1f} "
          f"recordings/min  ({loop_ok} ok)")
    for key, label in (("one_worker", "Dask, 1 worker:"), ("two_workers", "Dask, 2 workers:")):
        r = out[key]
        print(f"{label:24s} {r['seconds']:8.1f} s  {r['per_minute']:6.1f} recordings/min  "
              f"({r['ok']} ok; peak memory per worker "
              + ", ".join(f"{m:.0f} MB" for m in r["peak_rss_mb"]) + ")")
    print(f"speed-up 2 workers / 1 worker: {out['speed_up']:.2f}x (target >= 1.7x)")
    print(f"Dask overhead, 1 worker against the plain loop: {100 * out['overhead']:+.1f} % "
          f"(target <= 10 %)")
    print(f"load average (1 min) before {load[0]:.1f}, after {load[1]:.1f} (2 cores)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
