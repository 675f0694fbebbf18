"""``pmsm-sysid record --out BAG``: record the topics (inputs and outputs) into a rosbag2."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from .common import count, live_seconds, ros_name

HELP = "records the topics (inputs and outputs) to a rosbag2"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file", "out": "bag"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, metavar="BAG", help="rosbag2 directory to create")
    p.add_argument("--namespace", type=ros_name, default="/pmsm",
                   help="the pipeline's namespace (default /pmsm)")
    p.add_argument("--topics", nargs="+", type=ros_name, metavar="TOPIC", default=None,
                   help="record exactly these topics (relative names are taken in the "
                        "namespace; default: the inputs <ns>/thrust|speed|position, the "
                        "results <ns>/model|ridges|ridge_frequencies|validation|change and "
                        "<ns>/stats/*); other types are taken from their publishers")
    p.add_argument("--duration", type=live_seconds, default=None, metavar="S",
                   help="stop after S seconds (default: until Ctrl-C or SIGTERM)")
    p.add_argument("--storage", choices=("sqlite3", "mcap"), default="sqlite3",
                   help="storage plugin (default sqlite3: flushed every second, survives "
                        "being killed)")
    p.add_argument("--depth", type=count(1, 1_000_000), default=10000, metavar="N",
                   help="subscription queue depth per topic (default 10000)")
    p.add_argument("--force", action="store_true", help="replace an existing bag at --out")
    p.add_argument("--json", metavar="FILE", default=None,
                   help="write a summary as JSON ('-' = stdout)")




def _drain(session: Any, node: Any, quiet_s: float = 0.3, max_s: float = 3.0) -> None:
    """After a stop, keep what already arrived, however slow this process is.

    First every message received before the stop is taken from the queues (bounded by what
    is queued, not by a clock); then the executor spins until no message came for
    ``quiet_s`` (at most ``max_s``) to take what was in flight when the stop came.
    """
    import time

    node.take_received_before(time.time_ns())
    end = time.monotonic() + max_s
    last_total, last_change = node.total, time.monotonic()
    while time.monotonic() < end and time.monotonic() - last_change < quiet_s:
        session.executor.spin_once(timeout_sec=0.02)
        if node.total != last_total:
            last_total, last_change = node.total, time.monotonic()


def summary_line(out: Path, counts: dict[str, int], seconds: float) -> str:
    per_topic = ", ".join(f"{t} {n}" for t, n in sorted(counts.items())) or "no messages"
    return f"recorded {out}: {sum(counts.values())} messages in {seconds:.1f} s ({per_topic})"


def run(args: argparse.Namespace) -> int:
    import time

    from ..bagio import BagRecorder
    from ..core.errors import PmsmSysidError
    from ..nodes.recorder import RecorderNode
    from ..rosargs import prepared
    from ..rosutil import check_namespace, ros_session, stop_on_signals
    from .common import replace_bag_dir, write_json

    namespace = check_namespace(args.namespace)
    if args.duration is not None and not args.duration > 0:
        raise PmsmSysidError(f"--duration must be > 0, got {args.duration}")
    if args.depth < 1:
        raise PmsmSysidError(f"--depth must be >= 1, got {args.depth}")
    out = Path(args.out)
    replace_bag_dir(out, args.force)
    info = sys.stderr if args.json == "-" else sys.stdout
    with prepared(getattr(args, "ros_args", None) or [], namespace) as ros_args, \
            ros_session(ros_args=ros_args) as session, stop_on_signals(session.stop), \
            BagRecorder(out, storage=args.storage) as recorder:
        node = session.add(RecorderNode(recorder, context=session.context,
                                        namespace=namespace, topics=args.topics,
                                        depth=args.depth))
        print(f"recording {', '.join(sorted(node.types) + sorted(node.pending))} into {out} "
              "(Ctrl-C to stop)", file=info, flush=True)
        start = time.monotonic()
        session.spin_for(args.duration)
        _drain(session, node)
        seconds = time.monotonic() - start
        counts = dict(node.counts)
    print(summary_line(out, counts, seconds), file=info, flush=True)
    write_json({"out": str(out), "storage": args.storage, "messages": sum(counts.values()),
                "topics": counts, "seconds": seconds}, args.json)
    return 0
