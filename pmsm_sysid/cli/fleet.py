"""``pmsm-sysid fleet RECORDING... (--plant PLANT | --sim SIM_BAG) --out DIR``: a fleet of
axes.

For every recording (paths, directories searched for rosbag2 recordings, glob patterns) and
every axis in it: the fitted physical plant (mass, viscous friction, the library's effects
with standard errors and confidence) and the diagnosis of the reference on it (a plant
file, or a recording of the user's simulator compared as ``diagnose --sim`` does), run in
parallel on Dask distributed: a local cluster of ``--workers`` processes, or an existing
cluster through ``--scheduler tcp://HOST:PORT``. One table, ``DIR/results.parquet`` (one row
per recording axis, kept readable as it grows); per axis, each parameter against its own
baseline, alarms in ``DIR/alarms.json``, trends on ``DIR/index.html``. ``--resume`` adds to
a batch (killed, or with new recordings), skipping what is done by content. Exit status 0
when every recording was analysed, 1 when some failed (each is a row with its reason).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from .common import budget, count, number, parse_fraction, ros_name, write_json

HELP = ("many recordings in parallel on Dask: each axis's fitted plant, a Parquet table, "
        "per-axis trends and drift alarms")
#: Output options, checked before any work starts (see common.check_outputs); --out is a
#: directory with rules of its own (new, empty, or one a fleet batch wrote).
OUTPUTS = {"json": "file"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..batch.cluster import CONNECT_TIMEOUT_S

    p.add_argument("recordings", nargs="*", metavar="RECORDING",
                   help="rosbag2 recordings: paths, directories (searched) or glob patterns")
    ref = p.add_mutually_exclusive_group(required=True)
    ref.add_argument("--plant", metavar="PLANT.yaml",
                     help="the reference plant each recording is diagnosed against")
    ref.add_argument("--sim", metavar="SIM_BAG",
                     help="a recording of your simulator as the reference instead (its plant "
                          "is fitted once per worker, each recording compared with it)")
    p.add_argument("--sim-namespace", type=ros_name, default=None,
                   help="topic namespace or JointState topic of --sim (default: auto-detect)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output directory: results.parquet, alarms.json, index.html")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=count(1, 1024), default=None, metavar="N",
                       help="worker processes of the local Dask cluster (default: one per "
                            "CPU; never more than recordings to analyse; a single one is "
                            "analysed in this process, without a cluster)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="run on an existing Dask cluster (dask scheduler / dask worker)")
    p.add_argument("--connect-timeout", type=number(0, None, low_open=True, unit="s"),
                   default=CONNECT_TIMEOUT_S, metavar="S",
                   help=f"how long the --scheduler may take to answer (default "
                        f"{CONNECT_TIMEOUT_S:g} s)")
    p.add_argument("--resume", action="store_true",
                   help="add to the batch in --out: skip recordings already analysed there "
                        "(by content), retry the failed ones")
    p.add_argument("--namespace", type=ros_name, default=None,
                   help="read only this topic namespace or JointState topic (default: every "
                        "axis of each recording)")
    p.add_argument("--axis-from", choices=("topic", "parent"), default="topic",
                   help="name axes by their topic namespace / joint (default), or by the "
                        "directory holding the recording")
    p.add_argument("--min-duration", type=number(0, None, low_open=True, unit="s"),
                   default=5.0, metavar="S",
                   help="shorter recordings are a row with status error (default 5 s)")
    p.add_argument("--alpha", type=parse_fraction, default=1e-3,
                   help="family-wise false-alarm level of each effect selection step "
                        "(default 1e-3)")
    p.add_argument("--min-share", type=parse_fraction, default=0.01,
                   help="smallest share of the mismatch an effect must explain (default 0.01)")
    p.add_argument("--max-samples", type=budget, default=120_000, metavar="N",
                   help="samples used at most of each recording (default 120000, at least "
                        "20000); a longer one is used in ten spans spread evenly over it, and "
                        "only those are read")
    p.add_argument("--baseline", type=count(3, 10_000), default=8, metavar="N",
                   help="an axis's first N recordings are its baseline (default 8)")
    p.add_argument("--band", type=number(0, 100, low_open=True), default=4.0, metavar="Z",
                   help="band half-width in standard deviations, i.e. the false-alarm level "
                        "of one comparison (default 4: p = 6e-5)")
    p.add_argument("--min-change", type=number(0, 1), default=0.02, metavar="F",
                   help="smallest relative change alarmed (default 0.02 = 2%%)")
    p.add_argument("--json", metavar="FILE", help="write a summary as JSON ('-' = stdout)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar (there is none when stderr is not a terminal)")
    p.add_argument("--force", action="store_true",
                   help="start the batch in --out again (never a directory of other things)")


class _Bars:
    """The progress callback: a bar while reading the recordings, one while analysing."""

    def __init__(self) -> None:
        from ..progress import Bar

        self.Bar = Bar
        self.bar: Any = None
        self.stage = ""
        self.done = 0

    def __call__(self, p: Any) -> None:
        if p.stage != self.stage:
            self.close()
            self.stage = p.stage
            counts = ("failed",) if p.stage == "analysing" else ()
            label = "fleet" if p.stage == "analysing" else p.stage
            self.bar = self.Bar(p.total, label, counts=counts, rate=p.stage == "analysing")
            self.done = 0
        if p.done > self.done:
            extra = {"failed": p.failed} if p.stage == "analysing" else {}
            self.bar.update(p.done - self.done, **extra)
            self.done = p.done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def run(args: argparse.Namespace) -> int:
    from ..api.fleet_batch import fleet

    bars = _Bars()
    out = sys.stderr if args.json == "-" else sys.stdout
    try:
        result = fleet(args.recordings, args.plant, sim=args.sim,
                       sim_namespace=args.sim_namespace, scheduler=args.scheduler,
                       workers=args.workers, out=args.out, resume=args.resume,
                       force=args.force, namespace=args.namespace, axis_from=args.axis_from,
                       min_duration=args.min_duration, alpha=args.alpha,
                       min_share=args.min_share, max_samples=args.max_samples,
                       baseline=args.baseline, z=args.band,
                       min_change=args.min_change, progress=bars,
                       connect_timeout=args.connect_timeout)
    except KeyboardInterrupt:
        bars.close()
        print(f"fleet: interrupted after {bars.done if bars.stage == 'analysing' else 0} "
              f"row(s); every finished row is in {args.out}/results.parquet; --resume "
              "continues", file=sys.stderr)
        return 130
    finally:
        bars.close()
    write_json(result.to_dict(), args.json)
    if result.summary():
        print(result.summary(), file=out)
    f = result.files
    print(f"fleet: {result.analysed} recording axes analysed, {result.failed} failed"
          f"{f', {result.skipped} done before' if result.skipped else ''}"
          f"{f', {result.duplicates} duplicate(s)' if result.duplicates else ''}; "
          f"{len(result.alarms)} alarm(s); {result.table.num_rows} rows in {f['table']}; "
          f"alarms {f['alarms']}; page {f['page']}", file=out)
    return 1 if result.failed else 0
