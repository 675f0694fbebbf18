"""``pmsm-sysid monitor``: live view of the package's topics (rates, last values, gaps, results)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

HELP = "live view of the topics: rates, last values, gaps, latest model, ridges, validation"
CLEAR = "\x1b[H\x1b[2J"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--namespace", default="/pmsm", help="input namespace (default /pmsm)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: until Ctrl-C; 3 s with --once)")
    p.add_argument("--once", action="store_true",
                   help="listen for --duration seconds, print one snapshot and exit")
    p.add_argument("--interval", type=float, default=0.5, metavar="S",
                   help="refresh period (default 0.5 s)")
    p.add_argument("--json", metavar="FILE", default=None,
                   help="write the last snapshot as JSON ('-' = stdout)")


def render(snap: dict[str, Any], elapsed_s: float) -> str:
    """The full-screen view of one snapshot."""
    from ..core.monitoring import render_sysid, render_topics

    head = f"pmsm-sysid monitor  namespace {snap['namespace']}  t = {elapsed_s:.1f} s"
    return "\n".join([head, "", *render_topics(snap["topics"]), "",
                      *render_sysid(snap["sysid"])])


def render_line(snap: dict[str, Any], elapsed_s: float) -> str:
    """One line per update (when stdout is not a terminal)."""
    parts = [f"t={elapsed_s:.1f}s"]
    for s in snap["topics"]:
        if s["count"] or s["topic"].startswith(snap["namespace"].rstrip("/") + "/"):
            name = s["topic"].rsplit("/", 1)[-1]
            parts.append(f"{name} n={s['count']} {s['rate_hz']:.0f}Hz gaps={s['gaps']}")
    model = snap["sysid"]["model"]
    if model is not None and "n_terms" in model:
        parts.append(f"model {model['n_terms']} terms")
    validation = snap["sysid"]["validation"]
    if validation:
        parts.append("validation " + ("PASS" if all(v["passed"] for v in validation) else "FAIL"))
    return " | ".join(parts)


def _check(args: argparse.Namespace) -> float | None:
    from ..core.errors import PmsmSysidError

    if args.interval <= 0:
        raise PmsmSysidError(f"--interval must be > 0, got {args.interval}")
    if args.duration is not None and args.duration <= 0:
        raise PmsmSysidError(f"--duration must be > 0, got {args.duration}")
    duration: float | None = args.duration
    if args.once and duration is None:
        duration = 3.0
    return duration


def run(args: argparse.Namespace) -> int:
    import time

    from ..nodes.monitor import MonitorNode
    from ..rosutil import ros_session, stop_on_signals
    from .common import write_json

    duration = _check(args)
    tty = sys.stdout.isatty() and args.json != "-"
    with ros_session() as session, stop_on_signals(session.stop):
        node = session.add(MonitorNode(context=session.context, namespace=args.namespace))
        start = time.monotonic()
        snap = node.snapshot()
        while not session.stop.is_set():
            left = None if duration is None else duration - (time.monotonic() - start)
            if left is not None and left <= 0:
                break
            session.spin_for(args.interval if left is None else min(args.interval, left))
            snap = node.snapshot()
            if not args.once and args.json != "-":
                elapsed = time.monotonic() - start
                text = render(snap, elapsed) if tty else render_line(snap, elapsed)
                print((CLEAR + text) if tty else text, flush=True)
        if args.once and args.json != "-":
            print(render(snap, time.monotonic() - start), flush=True)
    write_json(snap, args.json)
    return 0
