"""Reading the spans of a long recording, not the recording: memory and time stay bounded.

A bag holding more samples than the fitting stages use (:mod:`pmsm_sysid.core.recording.
spans`) is read span by span. The bag's index says how many samples it holds (the messages
on the position topic) and over how long; the spans are planned on that count, and each is
read through the storage's time index (MCAP chunk index, SQLite index on the log time):
the messages logged within the span's time, widened by a margin for the gap between the
log time and ``header.stamp``, of which those stamped within the span are kept. A span
that comes out short of what was planned (log times drifting from the stamps by more
than the margin) is read again by a scan of the whole bag, still keeping only its own
messages. Each span is aligned on its own (:func:`.read.read_recording`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .. import topics as tp
from ..core.errors import BagError
from ..core.recording.spans import MAX_SAMPLES, Excerpt, excerpt_of, join, plan_spans
from .cdr import decode_stamped
from .common import open_reader, typestore
from .read import Window, _choose_layout, _stamp_ns, read_recording

#: Log-time margin around a span (ns): the recorder's delay between stamp and log time.
MARGIN_NS = 2_000_000_000
#: A span read through the time index must hold this share of its planned samples.
MIN_SHARE = 0.95


def _extent(path: Path, namespace: str | None) -> tuple[int, int, int, int]:
    """(samples, first stamp ns, its log time ns, duration ns) from the bag's index."""
    with open_reader(path) as reader:
        found = {c.topic: c.msgtype for c in reader.connections}
        layout = _choose_layout(path, found, namespace)
        topic = layout.get("joint_state") or layout[tp.POSITION]
        conns = [c for c in reader.connections if c.topic == topic]
        count = sum(int(c.msgcount) for c in conns)
        first = next(iter(reader.messages(connections=conns)), None)
        if first is None:
            raise BagError(f"{path}: no messages on {topic} (empty recording)")
        conn, logged, data = first
        got = decode_stamped(data) if conn.msgtype != tp.JOINT_STATE_TYPE else None
        stamp = got[0] if got is not None else _stamp_ns(
            typestore().deserialize_cdr(data, conn.msgtype))
        return count, stamp, int(logged), int(reader.duration)


def read_excerpt(path: str | Path, *, namespace: str | None = None,
                 max_samples: int = MAX_SAMPLES, split: float | None = None) -> Excerpt:
    """The spans of the bag at ``path`` that :func:`plan_spans` chooses, read apart.

    A bag within ``max_samples`` is read whole (:func:`.read.read_recording`). ``split``:
    the end of the recording is held out (spans planned on each side of the cut).
    """
    path = Path(path)
    count, stamp0, log0, duration = _extent(path, namespace)
    if count <= max_samples or duration <= 0:
        rec = read_recording(path, namespace=namespace).recording
        return excerpt_of(rec, plan_spans(len(rec), max_samples, split))
    period = duration / max(count - 1, 1)  # ns per sample, from the index
    parts = []
    for a, b in plan_spans(count, max_samples, split):
        lo = stamp0 + round((a - 0.5) * period)
        hi = stamp0 + round((b - 0.5) * period)
        shift = log0 - stamp0
        window: Window = (lo + shift - MARGIN_NS, hi + shift + MARGIN_NS, lo, hi)
        rec = _span(path, namespace, window)
        if len(rec) < MIN_SHARE * (b - a):  # log times far from the stamps: scan the bag
            rec = _span(path, namespace, (None, None, lo, hi))
        if len(rec) < 2:
            raise BagError(f"{path}: no aligned samples in span {a}:{b} of its {count}")
        start = round((rec.t[0] * 1e9 - stamp0) / period)
        parts.append((rec, max(0, min(int(start), count - len(rec)))))
    return join(parts, count)


def _span(path: Path, namespace: str | None, window: Window) -> Any:
    return read_recording(path, namespace=namespace, window=window).recording


__all__ = ["read_excerpt"]
