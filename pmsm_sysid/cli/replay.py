"""``pmsm-sysid replay BAG``: publish a recording on its topics, paced by its timestamps."""

from __future__ import annotations

import argparse
import sys

from .common import count, number, ros_name, wait_seconds

HELP = "publishes a recording on the topics (--rate, --loop)"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file"}
#: How long the replay waits, after the last message, for every reliable subscriber to
#: acknowledge what it was sent. Normally milliseconds; a subscriber's process starved on a
#: busy machine acknowledges late, and leaving earlier would lose the tail it had not yet
#: received (seen: 56 of 6000 messages after a fixed 2 s). A bound, not a pace.
ACK_WAIT_S = 30.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory (or .mcap/.db3 file)")
    p.add_argument("--rate", type=number(0, 1e6), default=1.0, metavar="R",
                   help="speed factor on the recorded timing (default 1; 0 = as fast as the "
                        "subscribers' queues allow, same as --fast)")
    p.add_argument("--fast", action="store_true", help="same as --rate 0")
    p.add_argument("--loop", nargs="?", type=count(0, 1_000_000), const=0, default=1,
                   metavar="N",
                   help="repeat N times (no N: until Ctrl-C); stamps are shifted forward on "
                        "each pass so they keep increasing")
    p.add_argument("--namespace", type=ros_name, default=None,
                   help="publish the recorded pipeline's topics (inputs and results) under "
                        "this namespace instead of the recorded one")
    p.add_argument("--wait", type=wait_seconds, default=10.0, metavar="S",
                   help="wait up to S seconds for subscribers on the input topics before "
                        "starting (default 10; 0 = start at once)")
    p.add_argument("--subscribers", type=count(1, 1000), default=1, metavar="N",
                   help="wait for N subscribers on each input topic (default 1; e.g. 2 for an "
                        "identifier that also records)")
    p.add_argument("--burst", type=count(1, 1_000_000), default=500, metavar="N",
                   help="with --fast: messages per topic per burst (default 500)")
    p.add_argument("--drain-rate", type=number(0, 1e9, low_open=True),
                   default=5000.0, metavar="MSG_PER_S",
                   help="with --fast: pause after each burst as for a subscriber taking this "
                        "many messages per second (default 5000)")
    p.add_argument("--json", metavar="FILE", default=None,
                   help="write a summary as JSON ('-' = stdout)")


def _check(args: argparse.Namespace) -> float:
    from ..core.errors import PmsmSysidError

    rate = 0.0 if args.fast else args.rate
    if not rate >= 0 or rate == float("inf"):
        raise PmsmSysidError(f"--rate must be >= 0, got {args.rate}")
    if args.loop < 0:
        raise PmsmSysidError(f"--loop must be >= 0, got {args.loop}")
    if args.wait < 0:
        raise PmsmSysidError(f"--wait must be >= 0, got {args.wait}")
    if args.subscribers < 1:
        raise PmsmSysidError(f"--subscribers must be >= 1, got {args.subscribers}")
    if args.burst < 1 or not args.drain_rate > 0:
        raise PmsmSysidError("--burst must be >= 1 and --drain-rate > 0")
    return rate


def _topic_line(topic: str, messages: int, subscribers: int, at_start: int) -> str:
    who = {0: "no subscriber", 1: "1 subscriber"}.get(subscribers, f"{subscribers} subscribers")
    late = f" ({at_start} when it began)" if at_start < subscribers else ""
    return f"{topic} {messages} to {who}{late}"


def run(args: argparse.Namespace) -> int:
    import time

    from ..nodes.replayer import ReplayerNode
    from ..rosargs import prepared
    from ..rosutil import check_namespace, ros_session, stop_on_signals
    from .common import write_json

    rate = _check(args)
    namespace = None if args.namespace is None else check_namespace(args.namespace)
    info = sys.stderr if args.json == "-" else sys.stdout
    with prepared(getattr(args, "ros_args", None) or [], (namespace or "/")) as ros_args, \
            ros_session(ros_args=ros_args) as session, stop_on_signals(session.stop):
        node = session.add(ReplayerNode(
            args.bag, context=session.context, rate=rate, loops=args.loop,
            namespace=namespace, wait_s=args.wait, burst=args.burst,
            subscribers=args.subscribers, drain_rate=args.drain_rate))
        for topic, msgtype in sorted(node.skipped.items()):
            print(f"replay: skipping {topic} ({msgtype}: no Python type for it here)",
                  file=sys.stderr)
        topics = ", ".join(sorted(node.remap.values()))
        print(f"replaying {args.bag} on {topics} at "
              f"{'full speed' if rate == 0 else f'{rate:g}x'}", file=info, flush=True)
        start = time.monotonic()
        session.spin_until(lambda: node.finished)
        if not node.stats.matched:
            had = min(node.stats.at_start.get(t, 0) for t in node.wait_for)
            print(f"replay: {had} of {args.subscribers} subscriber(s) on "
                  f"{', '.join(node.wait_for)} after {args.wait:g} s; published anyway",
                  file=sys.stderr)
        if not node.flush_acks(ACK_WAIT_S):
            print(f"replay: a subscriber did not acknowledge every message within "
                  f"{ACK_WAIT_S:g} s; it may have missed the last ones", file=sys.stderr)
        seconds = time.monotonic() - start
        stats = node.stats
    total = sum(stats.counts.values())
    listeners = {t: stats.listeners.get(t, 0) for t in sorted(node.remap.values())}
    per_topic = ", ".join(_topic_line(t, stats.counts.get(t, 0), n, stats.at_start.get(t, 0))
                          for t, n in listeners.items())
    print(f"replayed {args.bag}: {total} messages in {stats.passes} pass(es), {seconds:.1f} s "
          f"({per_topic})", file=info, flush=True)
    if not any(listeners.get(t) for t in node.wait_for):
        print(f"replay: nobody listened: no subscriber on {', '.join(node.wait_for)} while "
              "replaying", file=sys.stderr)
    write_json({"bag": str(args.bag), "messages": total, "topics": dict(stats.counts),
                "subscribers": listeners, "subscribers_at_start": stats.at_start,
                "passes": stats.passes, "seconds": seconds,
                "matched": stats.matched, "interrupted": not node.finished}, args.json)
    return 0
