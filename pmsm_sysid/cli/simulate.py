"""``pmsm-sysid simulate``: run the motor model offline and write a recording."""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .common import MAX_AMPLITUDE_N, number, ros_name, seed_type

if TYPE_CHECKING:
    from ..core.recording.signals import Recording

HELP = "offline: run the motor model faster than real time and write a recording"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file", "out": "bag"}

EXCITATIONS = ("paper-speed", "paper-position", "multisine", "chirp", "prbs", "aprbs",
               "broadband")


def _option(text: str) -> tuple[str, Any]:
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got '{text}'")
    value: Any = raw
    for conv in (int, float):
        try:
            value = conv(raw)
            break
        except ValueError:
            continue
    return key.strip(), value


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", metavar="PLANT.yaml",
                   help="plant file (default: the nominal motor of the paper's Table 1)")
    p.add_argument("--excitation", choices=EXCITATIONS, default="paper-speed",
                   help="thrust signal (default paper-speed: 16.5 Hz; paper-position: 11.5 Hz)")
    p.add_argument("--duration", type=number(0, None, low_open=True, unit="s"),
                   default=10.0, metavar="S",
                   help="seconds to simulate (default 10 = 5000 samples at 500 Hz)")
    p.add_argument("--seed", type=seed_type, default=0, metavar="N",
                   help="seed of the noise and of the random excitations (default 0)")
    p.add_argument("--amplitude", type=number(0, MAX_AMPLITUDE_N, unit="N"),
                   default=None, metavar="N",
                   help="peak thrust in newtons (default depends on --excitation)")
    p.add_argument("--excitation-option", type=_option, action="append", default=[],
                   metavar="KEY=VALUE", help="excitation option, e.g. f_max_hz=60 (repeatable)")
    p.add_argument("--out", required=True, metavar="BAG", help="rosbag2 directory to write")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap",
                   help="rosbag2 storage plugin (default mcap)")
    p.add_argument("--namespace", type=ros_name, default="/pmsm",
                   help="topic namespace (default /pmsm)")
    p.add_argument("--force", action="store_true", help="replace an existing bag at --out")
    p.add_argument("--json", metavar="FILE", help="write a summary as JSON ('-' = stdout)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar on the terminal (there is none when not a terminal)")




def run(args: argparse.Namespace) -> int:
    from ..api.simulation import simulation_plan
    from ..bagio.write import recording_writer
    from ..core.physics.motor import effective_substeps
    from ..core.physics.plant import plant_to_dict
    from ..progress import activity
    from ..validate import atomic_dir
    from .common import write_json

    out = Path(args.out)
    started = time.perf_counter()
    with activity("simulate") as say:
        plan = simulation_plan(args.plant, excitation=args.excitation, duration=args.duration,
                               seed=args.seed, amplitude=args.amplitude,
                               excitation_options=dict(args.excitation_option))
        stats = _Stats()
        with atomic_dir(out, "--out") as tmp:  # complete, or not there at all
            blocks = stats.timed(plan.blocks())
            first = next(blocks)
            with recording_writer(tmp, first, namespace=args.namespace,
                                  storage=args.storage) as writer:
                writer.write(first)
                for block in blocks:  # one block in memory at a time
                    say(f"written {stats.n - len(block)} of {plan.samples} samples")
                    writer.write(block)
    total_s = time.perf_counter() - started
    plant, source = plan.plant, plan.source
    n, fs = stats.n, plant.sample_rate_hz
    summary = {
        "out": str(out), "storage": args.storage, "namespace": args.namespace,
        "samples": n, "sample_rate_hz": fs, "duration_s": n / fs,
        "excitation": args.excitation, "amplitude_n": source.amplitude_n,
        "excitation_options": source.options, "seed": args.seed,
        "plant_file": plan.plant_label, "plant": plant_to_dict(plant),
        "effects": list(plant.effects), "rk4_substeps": effective_substeps(plant),
        "thrust_rms_n": stats.std("thrust"), "speed_rms_mps": stats.std("speed"),
        "position_min_m": stats.low, "position_max_m": stats.high,
        "simulate_s": stats.seconds, "total_s": total_s, "realtime_factor": (n / fs) / total_s,
    }
    effects = ", ".join(plant.effects) or "none"
    print(f"wrote {out}: {n} samples at {fs:g} Hz ({n / fs:g} s), {args.excitation} "
          f"{source.amplitude_n:g} N, seed {args.seed}, effects: {effects}; "
          f"{total_s:.2f} s ({summary['realtime_factor']:.0f}x real time)",
          file=sys.stderr if args.json == "-" else sys.stdout)
    write_json(summary, args.json)
    return 0


class _Stats:
    """Standard deviations and the position range over blocks (the summary's numbers)."""

    def __init__(self) -> None:
        self.n = 0
        self.seconds = 0.0  # spent simulating
        self.low, self.high = math.inf, -math.inf
        self._sum = {"thrust": 0.0, "speed": 0.0}
        self._sq = {"thrust": 0.0, "speed": 0.0}

    def add(self, rec: Recording) -> None:
        self.n += len(rec)
        self.low = min(self.low, float(rec.position.min()))
        self.high = max(self.high, float(rec.position.max()))
        for name in self._sum:
            x = rec.signal(name)
            self._sum[name] += float(x.sum())
            self._sq[name] += float(x @ x)

    def timed(self, blocks: Iterator[Recording]) -> Iterator[Recording]:
        """The blocks, each added to the statistics and its simulation timed."""
        while True:
            t0 = time.perf_counter()
            block = next(blocks, None)
            self.seconds += time.perf_counter() - t0
            if block is None:
                return
            self.add(block)
            yield block

    def std(self, name: str) -> float:
        mean = self._sum[name] / self.n
        return math.sqrt(max(self._sq[name] / self.n - mean * mean, 0.0))
