"""How long a recorded run takes to end: the package's Fast DDS profile against Fast DDS's
defaults.

``pmsm-sysid run --duration 5 --record BAG`` (its own process, as a user runs it) ends by
waiting until the recorder, a process of its own, has acknowledged the last samples.
Fast DDS's writers ask for acknowledgements with a heartbeat every 3 s; the package's
profile (``pmsm_sysid/data/fastdds_profile.xml``, :mod:`pmsm_sysid.dds`) every 0.1 s. The
runs alternate between the two (the default through a profile file that sets nothing,
which the package leaves alone as a user's choice), each must record every sample, and
the medians of the wall times and their ratio are printed; on a shared machine only
interleaved runs compare.

Usage: ``python bench/run_end_bench.py [--repeat 3] [--duration 5]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pmsm_sysid.dds import PROFILE_VARIABLES


def one_run(duration: float, profile: str | None) -> float:
    """Wall seconds of one recorded run (its process from start to exit)."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {k: v for k, v in os.environ.items() if k not in PROFILE_VARIABLES}
        env.update(ROS_LOG_DIR=str(Path(tmp) / "log"), ROS_DOMAIN_ID=env.get("ROS_DOMAIN_ID",
                                                                              "73"))
        if profile is not None:
            env[PROFILE_VARIABLES[0]] = profile
        out = Path(tmp) / "run.json"
        t0 = time.monotonic()
        proc = subprocess.run([sys.executable, "-m", "pmsm_sysid.cli", "run", "--duration",
                               str(duration), "--record", str(Path(tmp) / "bag"), "--json",
                               str(out)], env=env, cwd=tmp, capture_output=True, text=True,
                              timeout=600)
        wall = time.monotonic() - t0
        if proc.returncode != 0:
            raise SystemExit(f"run failed: {proc.stderr.strip()[-500:]}")
        s = json.loads(out.read_text())
        if s["record_samples_lost"] != 0 or s["samples_received"] != round(duration * 500):
            raise SystemExit(f"run lost data: {s['record_samples_lost']} samples not recorded,"
                             f" {s['samples_received']} received")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=5.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        plain = Path(tmp) / "defaults.xml"
        plain.write_text('<?xml version="1.0" encoding="UTF-8" ?>\n<profiles xmlns='
                         '"http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"/>\n')
        walls: dict[str, list[float]] = {"package profile": [], "Fast DDS defaults": []}
        for _ in range(args.repeat):
            walls["package profile"].append(one_run(args.duration, None))
            walls["Fast DDS defaults"].append(one_run(args.duration, str(plain)))
    for name, w in walls.items():
        print(f"{name:18s} wall {' '.join(f'{x:5.1f}' for x in w)} s, "
              f"median {statistics.median(w):.1f} s")
    ratio = statistics.median(walls["Fast DDS defaults"]) / statistics.median(
        walls["package profile"])
    print(f"a {args.duration:g} s recorded run ends {ratio:.2f}x sooner with the package's "
          "profile")


if __name__ == "__main__":
    main()
