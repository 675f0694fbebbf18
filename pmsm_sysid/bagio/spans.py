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

from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import topics as tp
from ..core.errors import BagError, DataError
from ..core.recording.signals import Recording
from ..core.recording.spans import MAX_SAMPLES, Excerpt, excerpt_of, join, plan_spans
from . import mcap_messages
from .cdr import decode_stamped
from .common import LoadedRecording, opened, reading, typestore
from .read import Window, _aligned, _choose_layout, _read_streams, _stamp_ns, check_all_finite

#: Log-time margin around a span (ns): the recorder's delay between stamp and log time.
MARGIN_NS = 2_000_000_000
#: A span read through the time index must hold this share of its planned samples.
MIN_SHARE = 0.95


def _stamp(conn: Any, data: bytes) -> int:
    got = decode_stamped(data) if conn.msgtype != tp.JOINT_STATE_TYPE else None
    if got is not None:
        return got[0]
    return _stamp_ns(typestore().deserialize_cdr(data, conn.msgtype))


def _position(path: Path, reader: Any, namespace: str | None) -> tuple[str, list[Any]]:
    """The topic whose messages count the samples (position, or the joint states) and its
    connections."""
    found = {c.topic: c.msgtype for c in reader.connections}
    layout = _choose_layout(path, found, namespace)
    topic = layout.get("joint_state") or layout[tp.POSITION]
    return topic, [c for c in reader.connections if c.topic == topic]


def _ends(path: Path, reader: Any, topic: str, conns: list[Any]) -> tuple[int, int, int]:
    """(first stamp, its log time, last stamp) in ns, from the first and last position
    messages (the last read through the time index)."""
    first = next(mcap_messages.messages(reader, conns), None)
    if first is None:
        raise BagError(f"{path}: no messages on {topic} (empty recording)")
    stamp0 = _stamp(first[0], first[2])
    tail = mcap_messages.messages(reader, conns, max(0, reader.end_time - MARGIN_NS))
    last = max((_stamp(conn, data) for conn, _, data in tail), default=stamp0)
    return stamp0, int(first[1]), last


def read_excerpt(path: str | Path, *, namespace: str | None = None,
                 max_samples: int = MAX_SAMPLES, split: float | None = None,
                 joint_name: str | None = None, use: str | None = None) -> Excerpt:
    """The spans of the bag at ``path`` that :func:`plan_spans` chooses, read apart.

    A bag within ``max_samples`` is read whole (:func:`.read.read_recording`). ``split``:
    the end of the recording is held out (spans planned on each side of the cut).
    ``joint_name``: the axis's joint of a JointState recording. ``use`` (what the samples
    are for, e.g. ``diagnose``): a non-finite sample in what is read is refused
    (:func:`.read.check_all_finite`); None: dropped, as on any read.
    """
    path = Path(path)
    with opened(path) as reader:  # opened once: rosbags parses its YAML on every open
        return _read_excerpt(path, reader, namespace, max_samples, split, joint_name, use)


def _read_excerpt(path: Path, reader: Any, namespace: str | None, max_samples: int,
                  split: float | None, joint_name: str | None, use: str | None) -> Excerpt:
    def read(window: Window | None) -> LoadedRecording:
        with reading(path):
            got = _read_streams(path, reader, namespace, joint_name, None, window)
        loaded = _aligned(path, got, None)
        if use is not None:
            check_all_finite(loaded, f"recording {path}", use)
        return loaded

    with reading(path):
        topic, conns = _position(path, reader, namespace)
        count = sum(int(c.msgcount) for c in conns)  # from the bag's index
        # a bag read whole needs no stamps of its ends (each look parses a chunk again)
        ends = None if 0 < count <= max_samples else _ends(path, reader, topic, conns)
    if ends is None or count <= max_samples or ends[2] <= ends[0]:
        whole = read(None).recording
        return excerpt_of(whole, plan_spans(len(whole), max_samples, split))
    stamp0, log0, stamp1 = ends
    period = (stamp1 - stamp0) / (count - 1)  # ns per sample
    parts = []
    for a, b in plan_spans(count, max_samples, split):
        lo = stamp0 + round((a - 0.5) * period)
        hi = stamp0 + round((b - 0.5) * period)
        shift = log0 - stamp0
        window: Window = (lo + shift - MARGIN_NS, hi + shift + MARGIN_NS, lo, hi)
        got = _span(read, window)
        if got is None or len(got) < MIN_SHARE * (b - a):  # log times far from the stamps:
            got = read((None, None, lo, hi)).recording  # scan the bag, keep the span
        rec = got
        start = round((rec.t[0] * 1e9 - stamp0) / period)
        parts.append((rec, max(0, min(int(start), count - len(rec)))))
    return join(parts, count)


def _span(read: Callable[[Window | None], LoadedRecording],
          window: Window) -> Recording | None:
    """The aligned samples of one span read through the time index, or None if too few
    were logged within its window to align (a refused non-finite sample stays refused)."""
    try:
        return read(window).recording
    except BagError:
        return None
    except DataError as exc:
        if "non-finite" in str(exc):
            raise
        return None


__all__ = ["read_excerpt"]
