"""Fleet benchmark: simulated recordings analysed in a plain loop and by ``ps.fleet`` on a
local Dask cluster of 1 worker and of 2 workers, in one run, interleaved.

The recordings: ``--recordings`` (default 200) of ``--duration`` s (default 10) over 4 axes,
each a drive (the packaged drive plant with 5 N of Coulomb friction) under the APRBS test
motion, each axis at its own mass. Each is analysed as ``pmsm-sysid fleet`` analyses it
(:func:`pmsm_sysid.api.fleet_row.recording_row`: the fitted plant and the diagnosis of the
nominal plant).

Interleaved: the machine is shared (2 cores, other work running) and its speed drifts by
10 % and more over the minutes a batch takes, so three batches run one after the other
would compare the machine at different times (two such runs gave Dask's overhead as -0.2 %
and +23 %). Instead the recordings are split into ``--rounds`` (default 4) equal rounds;
both clusters are started once, at the beginning (their start-up counted in their time),
and each round is analysed by all three -- the plain loop, 1 worker, 2 workers -- in an
order that rotates from round to round. Each total is the sum over the rounds. The loop
runs in a Python process of its own (the clusters' scheduler and nannies are threads of
this one), timed from after its imports.

Printed: recordings per minute of each; the speed-up of 2 workers over 1; Dask's overhead,
the time of 1 worker (cluster start, the worker's first imports, reading the recordings for
their content keys, scheduling, collecting the rows) over the plain loop's, minus one, in
total and per round; the peak resident memory of each worker process; and the CPU time each
used (this process -- the loop, or the Dask client, scheduler and nannies -- plus the
workers), whose ratio is Dask's overhead in work whatever else runs on the machine. The
load average before and after is printed with the figures, and whether the kernel groups
processes by session for CPU time (autogroup): then the workers of one session share that
session's part of the machine, and a second worker only speeds a batch up as far as the
other sessions leave CPU idle.

    .venv/bin/python bench/fleet_bench.py [--recordings 200] [--duration 10] [--rounds 4]
                                          [--json FILE]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy: one BLAS thread per process

REPO = Path(__file__).resolve().parents[1]
#: What a row imports on its first call (warm in a worker after its first row).
ROW_MODULES = ("pmsm_sysid.core.discrepancy", "pmsm_sysid.core.discrepancy.fitted",
               "pmsm_sysid.core.fleet", "pmsm_sysid.api.diagnosis", "pmsm_sysid.api.plantfit",
               "pmsm_sysid.core.selection.datacheck", "scipy.signal", "scipy.stats")
AXES = ("/axis1", "/axis2", "/axis3", "/axis4")
EPOCH = 1_767_571_200.0


def make_recordings(root: Path, indices: range, duration: float) -> float:
    """The recordings ``indices`` (over the four axes in turn) in ``root``; returns the
    seconds it took."""
    import pmsm_sysid as ps
    from pmsm_sysid.core.physics.plant import CoulombFriction

    start = time.perf_counter()
    base = dataclasses.replace(ps.Plant.from_yaml(REPO / "pmsm_sysid" / "data" / "drive.yaml"),
                               coulomb_friction=CoulombFriction(5.0))
    for i in indices:
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
    seconds). The modules a row uses are imported first (a worker has them after its
    first row)."""
    import importlib

    from pmsm_sysid.api.fleet_row import recording_row
    from pmsm_sysid.batch.inputs import all_units, expand
    from pmsm_sysid.core.physics.plant import load_plant

    for name in ROW_MODULES:
        importlib.import_module(name)
    plant = load_plant(REPO / "plants" / "nominal.yaml")
    start, cpu = time.perf_counter(), _cpu_s()
    units = list(all_units(expand([str(root)])))
    rows = [recording_row(u.path, plant, namespace=u.namespace, joint=u.joint, axis=u.axis,
                          content_sha256=u.content) for u in units]
    return (time.perf_counter() - start, sum(r["status"] == "ok" for r in rows),
            _cpu_s() - cpu)


def loop_in_a_process(root: Path) -> tuple[float, int, float]:
    """:func:`plain_loop` in a Python process of its own: the Dask clusters' scheduler and
    nannies run in threads of this one, and would take the interpreter from the loop."""
    proc = subprocess.run([sys.executable, __file__, "--loop", str(root)], check=True,
                          capture_output=True, text=True)
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    return float(got["seconds"]), int(got["ok"]), float(got["cpu_s"])


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


@dataclasses.dataclass
class DaskRuns:
    """One local cluster (started as the command starts it) and the rounds it analysed."""

    client: Any
    seconds: float  # the cluster's start, then each round's time added
    cpu_here: float = 0.0
    rounds: list[float] = dataclasses.field(default_factory=list)
    ok: int = 0

    def worker_cpu(self) -> float:
        """CPU seconds so far of the cluster's worker processes (its scheduler and nannies
        run in this process)."""
        return float(sum(self.client.run(_cpu_s).values()))

    def analyse(self, root: Path) -> None:
        import pmsm_sysid as ps

        start, cpu = time.perf_counter(), _cpu_s()
        result = ps.fleet(str(root), plant=REPO / "plants" / "nominal.yaml",
                          client=self.client)
        self.rounds.append(time.perf_counter() - start)
        self.seconds += self.rounds[-1]
        self.cpu_here += _cpu_s() - cpu
        self.ok += sum(s == "ok" for s in result.table.column("status").to_pylist())


def _autogroup() -> bool:
    try:
        return Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1"
    except OSError:
        return False


def _started(stack: ExitStack, workers: int) -> DaskRuns:
    from pmsm_sysid.batch.cluster import local_cluster

    start, cpu = time.perf_counter(), _cpu_s()
    client = stack.enter_context(local_cluster(workers))
    return DaskRuns(client, time.perf_counter() - start, _cpu_s() - cpu)


def run_rounds(rounds: list[Path]) -> dict[str, Any]:
    """Every round by the plain loop and by both clusters, the order rotating."""
    loop = {"seconds": 0.0, "cpu_s": 0.0, "ok": 0, "rounds": []}
    with ExitStack() as stack:
        one, two = _started(stack, 1), _started(stack, 2)
        for k, root in enumerate(rounds):
            order = ["loop", "one", "two"]
            for what in order[k % 3:] + order[:k % 3]:
                if what == "loop":
                    s, ok, cpu = loop_in_a_process(root)
                    loop["seconds"] += s
                    loop["cpu_s"] += cpu
                    loop["ok"] += ok
                    loop["rounds"].append(s)
                else:
                    (one if what == "one" else two).analyse(root)
        out: dict[str, Any] = {"loop": loop}
        for key, runs in (("one_worker", one), ("two_workers", two)):
            out[key] = {"seconds": runs.seconds, "ok": runs.ok, "rounds": runs.rounds,
                        "peak_rss_mb": sorted(runs.client.run(_peak_rss_mb).values()),
                        "cpu_s": {"client": runs.cpu_here, "workers": runs.worker_cpu()}}
    return out


def _print(out: dict[str, Any], load: list[float]) -> None:
    loop = out["loop"]
    print(f"plain loop, one process: {loop['seconds']:8.1f} s  {loop['per_minute']:6.1f} "
          f"recordings/min  ({loop['ok']} ok; CPU {loop['cpu_s']:.0f} s)")
    for key, label in (("one_worker", "Dask, 1 worker:"), ("two_workers", "Dask, 2 workers:")):
        r = out[key]
        print(f"{label:24s} {r['seconds']:8.1f} s  {r['per_minute']:6.1f} recordings/min  "
              f"({r['ok']} ok; CPU {r['cpu_s']['workers']:.0f} s in the workers, "
              f"{r['cpu_s']['client']:.0f} s here; peak memory per worker "
              + ", ".join(f"{m:.0f} MB" for m in r["peak_rss_mb"]) + ")")
    print(f"speed-up 2 workers / 1 worker: {out['speed_up']:.2f}x (target >= 1.7x)")
    print(f"Dask overhead, 1 worker against the plain loop: {100 * out['overhead']:+.1f} % "
          f"(target <= 10 %); per round (without the cluster's start): "
          + ", ".join(f"{100 * r:+.1f} %" for r in out["overhead_per_round"]))
    print(f"Dask overhead in CPU time, 1 worker against the plain loop: "
          f"{100 * out['cpu_overhead']:+.1f} %")
    print(f"load average (1 min) before {load[0]:.1f}, after {load[1]:.1f} (2 cores); CPU "
          f"time shared by session (autogroup): {'yes' if out['autogroup'] else 'no'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recordings", type=int, default=200)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--json", metavar="FILE")
    ap.add_argument("--loop", metavar="DIR", help=argparse.SUPPRESS)  # one round's loop
    args = ap.parse_args()
    if args.loop:
        s, ok, cpu = plain_loop(Path(args.loop))
        print(json.dumps({"seconds": s, "ok": ok, "cpu_s": cpu}))
        return
    n, k = args.recordings, max(1, args.rounds)
    load = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="fleet-bench-") as tmp:
        rounds = []
        made = 0.0
        for r in range(k):
            root = Path(tmp) / f"round{r}"
            root.mkdir()
            made += make_recordings(root, range(r * n // k, (r + 1) * n // k), args.duration)
            rounds.append(root)
        print(f"{n} recordings of {args.duration:g} s over {len(AXES)} axes written in "
              f"{made:.0f} s, analysed in {k} interleaved rounds")
        out: dict[str, Any] = run_rounds(rounds)
    load.append(os.getloadavg()[0])
    one, two, loop = out["one_worker"], out["two_workers"], out["loop"]
    for r in (loop, one, two):
        r["per_minute"] = 60 * n / r["seconds"]
    out.update({
        "recordings": n, "duration_s": args.duration, "rounds": k, "load_average": load,
        "autogroup": _autogroup(), "speed_up": one["seconds"] / two["seconds"],
        "overhead": one["seconds"] / loop["seconds"] - 1.0,
        "overhead_per_round": [a / b - 1.0 for a, b in zip(one["rounds"], loop["rounds"],
                                                            strict=True)],
        "cpu_overhead": sum(one["cpu_s"].values()) / loop["cpu_s"] - 1.0,
    })
    _print(out, load)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
