"""Bag I/O speed: a recording written and read a block / a chunk at a time against message by
message, in the same run.

Writes a simulated recording (``--seconds`` at 500 Hz: three topics) as an MCAP bag with the
block writer (``bagio.mcap_block``) and with ``rosbags``' writer called per message (the
files are the same, byte for byte: checked here too), then reads it with the chunk reader
(``bagio.mcap_arrays``) and with the message-by-message read (the samples are the same:
checked). Prints the median CPU seconds of ``--repeat`` interleaved runs of each and the
ratio message-by-message / block. CPU time (``time.process_time``), so a busy machine
slows both sides alike.

Usage: ``python bench/bagio_bench.py [--seconds 10] [--repeat 7]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import pmsm_sysid as ps
import pmsm_sysid.bagio.mcap_arrays as mcap_arrays
import pmsm_sysid.bagio.write as bag_write
from pmsm_sysid.bagio import read_recording, write_recording


def _cpu(fn: Callable[[], object]) -> float:
    start = time.process_time()
    fn()
    return time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    rec = ps.simulate("drive", excitation="broadband", duration=args.seconds, seed=1)
    block_writer, read_stamped = bag_write.block_writer, mcap_arrays.read_stamped
    times: dict[str, list[float]] = {k: [] for k in ("write block", "write each",
                                                      "read chunks", "read each")}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat + 1):  # the first round warms up (imports, caches)
            block, each = Path(tmp) / f"b{i}" / "bag", Path(tmp) / f"e{i}" / "bag"
            bag_write.block_writer = block_writer
            t_block = _cpu(lambda: write_recording(block, rec))  # noqa: B023
            bag_write.block_writer = lambda writer: None
            t_each = _cpu(lambda: write_recording(each, rec))  # noqa: B023
            bag_write.block_writer = block_writer
            assert (block / "bag.mcap").read_bytes() == (each / "bag.mcap").read_bytes()
            got: dict[str, object] = {}
            t_chunks = _cpu(lambda: got.update(a=read_recording(block)))  # noqa: B023
            mcap_arrays.read_stamped = lambda *a, **k: None
            t_read_each = _cpu(lambda: got.update(b=read_recording(block)))  # noqa: B023
            mcap_arrays.read_stamped = read_stamped
            a, b = got["a"].recording, got["b"].recording  # type: ignore[attr-defined]
            assert all(np.array_equal(getattr(a, k), getattr(b, k))
                       for k in ("t", "thrust", "speed", "position"))
            if i:
                for key, t in zip(times, (t_block, t_each, t_chunks, t_read_each),
                                  strict=True):
                    times[key].append(t)
    med = {k: statistics.median(v) for k, v in times.items()}
    n = len(rec)
    print(f"{n} samples ({3 * n} messages), median CPU of {args.repeat} interleaved runs:")
    for key, value in med.items():
        print(f"  {key:12s} {value * 1e3:7.1f} ms")
    print(f"write: {med['write each'] / med['write block']:.1f}x less CPU a block at a time; "
          f"read: {med['read each'] / med['read chunks']:.1f}x less CPU a chunk at a time")


if __name__ == "__main__":
    main()
