"""``pmsm-sysid simulate``: run the motor model offline and write a recording."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from .common import MAX_AMPLITUDE_N, number, ros_name, seed_type

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
    import numpy as np

    from ..api.simulation import simulation_run
    from ..bagio import write_recording
    from ..core.physics.motor import effective_substeps
    from ..core.physics.plant import plant_to_dict
    from ..progress import activity
    from ..validate import atomic_dir
    from .common import write_json

    out = Path(args.out)
    started = time.perf_counter()
    with activity("simulate") as say:
        sim = simulation_run(args.plant, excitation=args.excitation, duration=args.duration,
                             seed=args.seed, amplitude=args.amplitude,
                             excitation_options=dict(args.excitation_option))
        rec, plant, source = sim.recording, sim.plant, sim.source
        sim_s = time.perf_counter() - started
        say("writing the recording")
        with atomic_dir(out, "--out") as tmp:  # complete, or not there at all
            write_recording(tmp, rec, namespace=args.namespace, storage=args.storage)
    total_s = time.perf_counter() - started
    n, fs = len(rec), plant.sample_rate_hz
    summary = {
        "out": str(out), "storage": args.storage, "namespace": args.namespace,
        "samples": n, "sample_rate_hz": fs, "duration_s": n / fs,
        "excitation": args.excitation, "amplitude_n": source.amplitude_n,
        "excitation_options": source.options, "seed": args.seed,
        "plant_file": sim.plant_label, "plant": plant_to_dict(plant),
        "effects": list(plant.effects), "rk4_substeps": effective_substeps(plant),
        "thrust_rms_n": float(np.std(rec.thrust)), "speed_rms_mps": float(np.std(rec.speed)),
        "position_min_m": float(rec.position.min()), "position_max_m": float(rec.position.max()),
        "simulate_s": sim_s, "total_s": total_s, "realtime_factor": (n / fs) / total_s,
    }
    effects = ", ".join(plant.effects) or "none"
    print(f"wrote {out}: {n} samples at {fs:g} Hz ({n / fs:g} s), {args.excitation} "
          f"{source.amplitude_n:g} N, seed {args.seed}, effects: {effects}; "
          f"{total_s:.2f} s ({summary['realtime_factor']:.0f}x real time)",
          file=sys.stderr if args.json == "-" else sys.stdout)
    write_json(summary, args.json)
    return 0
