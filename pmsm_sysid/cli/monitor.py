"""``pmsm-sysid monitor``: live view of the package's topics (rates, last values, gaps, results).

On a terminal the view refreshes in place (like ``top``); piped, or with ``--once``, it prints
plain snapshots (no colours, no cursor movement). The view fits 80 columns; see
:mod:`.monitor_view` for what it shows.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, TextIO

from .common import live_seconds, number, ros_name

HELP = "live view of the topics: rates, last values, gaps, latest model, ridges, validation"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--namespace", type=ros_name, default="/pmsm",
                   help="the pipeline's namespace: its inputs and results (default /pmsm)")
    p.add_argument("--duration", type=live_seconds, default=None, metavar="S",
                   help="stop after S seconds (default: until Ctrl-C; 3 s with --once)")
    p.add_argument("--once", action="store_true",
                   help="listen for --duration seconds, print one snapshot and exit")
    p.add_argument("--interval", type=number(0, 3600, low_open=True, unit="s"),
                   default=0.5, metavar="S",
                   help="refresh period (default 0.5 s; piped: one snapshot per period)")
    p.add_argument("--json", metavar="FILE", default=None,
                   help="write the last snapshot as JSON ('-' = stdout)")


def console(file: TextIO | None = None, width: int | None = None) -> Any:
    """A rich console on ``file``: plain text (no colours, no cursor moves) unless a terminal."""
    from rich.console import Console

    out = sys.stdout if file is None else file
    tty = bool(getattr(out, "isatty", lambda: False)())
    return Console(file=out, width=width, force_terminal=tty, no_color=not tty,
                   highlight=False, emoji=False, soft_wrap=False)


def render(snap: dict[str, Any], elapsed_s: float, width: int = 80) -> str:
    """One snapshot as plain text ``width`` columns wide."""
    import io

    from .monitor_view import view

    buf = io.StringIO()
    con = console(buf, width)
    con.print(view(snap, elapsed_s))
    return buf.getvalue()


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
    import contextlib
    import time

    from rich.live import Live

    from ..nodes.monitor import MonitorNode
    from ..rosargs import prepared
    from ..rosutil import check_namespace, ros_session, stop_on_signals
    from .common import write_json
    from .monitor_view import nothing_received, view

    duration = _check(args)
    namespace = check_namespace(args.namespace)
    show = args.json != "-"
    con = console()
    live = show and not args.once and con.is_terminal
    with prepared(getattr(args, "ros_args", None) or [], namespace) as ros_args, \
            ros_session(ros_args=ros_args) as session, stop_on_signals(session.stop):
        node = session.add(MonitorNode(context=session.context, namespace=namespace))
        start = time.monotonic()
        snap = node.snapshot()
        screen = (Live(console=con, auto_refresh=False, transient=False) if live
                  else contextlib.nullcontext())
        with screen as shown:
            while not session.stop.is_set():
                left = None if duration is None else duration - (time.monotonic() - start)
                if left is not None and left <= 0:
                    break
                session.spin_for(args.interval if left is None else min(args.interval, left))
                snap = node.snapshot()
                elapsed = time.monotonic() - start
                if shown is not None:
                    shown.update(view(snap, elapsed), refresh=True)
                elif show and not args.once:
                    con.print(view(snap, elapsed))
                    con.print()
        if args.once and show:
            con.print(view(snap, time.monotonic() - start))
    hint = nothing_received(snap)
    if hint and not show:  # the view, when shown, holds the same line
        print(f"pmsm-sysid monitor: {hint}", file=sys.stderr)
    write_json(snap, args.json)
    return 0
