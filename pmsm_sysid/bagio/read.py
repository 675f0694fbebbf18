"""Reading recordings: find the input topics, decode ``header.stamp`` and values, align."""

from __future__ import annotations

from array import array
from collections.abc import Callable, Collection, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import topics as tp
from ..core.errors import BagError, DataError
from ..core.recording.align import align_streams, robust_period
from . import mcap_arrays, mcap_messages
from .cdr import decode_stamped
from .common import MAX_NONFINITE_LISTED, LoadedRecording, RawMessage, open_reader, typestore

SIGNALS = (tp.THRUST, tp.SPEED, tp.POSITION)
# (stamps in ns, values) of one stream while reading: 16 bytes a message, not ~70 in lists
_Stream = tuple["array[int]", "array[float]"]
#: Messages read per stream beyond the last sample asked for (reordered or late messages).
READ_MARGIN = 1000


def _stream() -> _Stream:
    return array("q"), array("d")


def _enough(streams: dict[str, _Stream], until: int | None) -> bool:
    """Every stream holds ``until`` + margin messages: the samples asked for are all read."""
    return until is not None and all(len(s[0]) >= until + READ_MARGIN for s in streams.values())


def bag_topics(path: str | Path) -> dict[str, str]:
    """Topic -> message type of every topic in the bag."""
    with open_reader(path) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def iter_raw(path: str | Path, topics: Collection[str] | None = None) -> Iterator[RawMessage]:
    """Every message (or those on ``topics``) in log order, CDR bytes as stored: for replay."""
    with open_reader(path) as reader:
        conns = list(reader.connections)
        if topics is not None:
            wanted = set(topics)
            missing = sorted(wanted - {c.topic for c in conns})
            if missing:
                have = ", ".join(sorted({c.topic for c in conns})) or "none"
                raise BagError(f"{path}: no topic {', '.join(missing)} (topics: {have})")
            conns = [c for c in conns if c.topic in wanted]
            if not conns:
                return
        for conn, stamp, data in reader.messages(connections=conns):
            yield RawMessage(conn.topic, conn.msgtype, int(stamp), bytes(data))


def _listing(found: dict[str, str]) -> str:
    return ", ".join(f"{k} ({v})" for k, v in sorted(found.items())) or "no topics at all"


def _check_type(path: Path, found: dict[str, str], topic: str, expected: str) -> None:
    if found[topic] != expected:
        raise BagError(f"{path}: {topic} has type {found[topic]}, expected {expected}")


def _triple(path: Path, found: dict[str, str], namespace: str) -> dict[str, str]:
    """signal -> topic for the three-topic layout under ``namespace`` (speed optional)."""
    chosen = {s: tp.input_topic(namespace, s) for s in SIGNALS}
    missing = [chosen[s] for s in (tp.THRUST, tp.POSITION) if chosen[s] not in found]
    if missing:
        raise BagError(f"{path}: no {' and no '.join(missing)} topic (topics: {_listing(found)})")
    if chosen[tp.SPEED] not in found:
        del chosen[tp.SPEED]
    for signal, topic in chosen.items():
        _check_type(path, found, topic, tp.INPUT_TYPES[signal])
    return chosen


def _choose_layout(path: Path, found: dict[str, str], namespace: str | None) -> dict[str, str]:
    """Either signal -> topic, or {"joint_state": topic} for the JointState layout."""
    if namespace is not None:
        if found.get(namespace) == tp.JOINT_STATE_TYPE:
            return {"joint_state": namespace}
        return _triple(path, found, namespace)
    suffix_t, suffix_p = "/" + tp.THRUST, "/" + tp.POSITION
    prefixes = sorted(t[: -len(suffix_t)] for t in found
                      if t.endswith(suffix_t) and t[: -len(suffix_t)] + suffix_p in found)
    if len(prefixes) == 1:
        return _triple(path, found, prefixes[0] or "/")
    if len(prefixes) > 1:
        raise BagError(f"{path}: several input namespaces ({', '.join(prefixes)}); say which "
                       f"to read, e.g. --namespace {prefixes[0] or '/'} (API: namespace=)")
    joints = sorted(t for t, m in found.items() if m == tp.JOINT_STATE_TYPE)
    if len(joints) == 1:
        return {"joint_state": joints[0]}
    if len(joints) > 1:
        raise BagError(f"{path}: several JointState topics ({', '.join(joints)}); say which "
                       f"to read, e.g. --namespace {joints[0]} (API: namespace=)")
    raise BagError(f"{path}: no <ns>/thrust + <ns>/position topics and no JointState topic "
                   f"(topics: {_listing(found)})")


def list_axes(path: str | Path) -> list[tuple[str, str | None]]:
    """Every axis a bag holds, as ``(namespace, joint)``: one per ``<ns>/thrust`` +
    ``<ns>/position`` pair (joint None), and one per joint of each ``JointState`` topic
    (namespace = that topic; the joints are read from its first message). Read each with
    ``read_recording(path, namespace=..., joint_name=...)``."""
    suffix_t, suffix_p = "/" + tp.THRUST, "/" + tp.POSITION
    with open_reader(path) as reader:
        found = {c.topic: c.msgtype for c in reader.connections}
        out: list[tuple[str, str | None]] = [
            (t[: -len(suffix_t)] or "/", None) for t in sorted(found)
            if t.endswith(suffix_t) and t[: -len(suffix_t)] + suffix_p in found]
        store = typestore()
        for topic in sorted(t for t, m in found.items() if m == tp.JOINT_STATE_TYPE):
            conns = [c for c in reader.connections if c.topic == topic]
            for conn, _, data in reader.messages(connections=conns):
                msg: Any = store.deserialize_cdr(data, conn.msgtype)
                out += [(topic, str(name)) for name in msg.name]
                break
    return out


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


_VALUE: dict[str, Callable[[Any], float]] = {
    tp.THRUST_TYPE: lambda m: float(m.wrench.force.x),
    tp.SPEED_TYPE: lambda m: float(m.twist.linear.x),
    tp.POSITION_TYPE: lambda m: float(m.point.x),
}


#: (log-time start, log-time stop, header-stamp lo, header-stamp hi) in ns, any None: one
#: span of a long recording (messages outside it are skipped, not held).
Window = tuple[int | None, int | None, int, int]
#: Every message (a stamp may be negative: a jittered clock starting at zero).
_WHOLE: Window = (None, None, -(2**63), 2**63 - 1)


def _read_triple(reader: Any, chosen: dict[str, str], until: int | None,
                 window: Window | None = None) -> tuple[dict[str, _Stream], bool]:
    store = typestore()
    by_topic = {topic: signal for signal, topic in chosen.items()}
    streams: dict[str, _Stream] = {s: _stream() for s in chosen}
    conns = [c for c in reader.connections if c.topic in by_topic]
    # the fast path only for the stock definitions (same type hash as ROS 2 Jazzy, or none)
    fast = {c.id for c in conns if c.digest in ("", store.hash_rihs01(c.msgtype))}
    start, stop, lo, hi = window or _WHOLE
    if conns and len(fast) == len(conns):  # a chunk at a time (mcap_arrays)
        names = list(streams)
        arrays = mcap_arrays.read_stamped(
            reader, conns, {c.id: names.index(by_topic[c.topic]) for c in conns},
            len(names), (start, stop, lo, hi), until, READ_MARGIN)
        if arrays is not None:
            return dict(zip(names, arrays[0], strict=True)), arrays[1]
    for conn, _, data in mcap_messages.messages(reader, conns, start, stop):
        stamps, values = streams[by_topic[conn.topic]]
        got = decode_stamped(data) if conn.id in fast else None
        if got is None:
            msg = store.deserialize_cdr(data, conn.msgtype)
            got = _stamp_ns(msg), _VALUE[conn.msgtype](msg)
        if not lo <= got[0] < hi:
            continue
        stamps.append(got[0])
        values.append(got[1])
        if len(stamps) % 256 == 0 and _enough(streams, until):
            return streams, True  # stopped early: the samples asked for are read
    return streams, False


def _joint_index(names: list[str], joint_name: str | None, seen: set[str]) -> int | None:
    seen.update(names)
    if joint_name is None:
        return 0 if len(names) == 1 else None
    return names.index(joint_name) if joint_name in names else None


def _read_joint(path: Path, reader: Any, topic: str, joint_name: str | None,
                until: int | None, window: Window | None = None,
                ) -> tuple[dict[str, _Stream], bool]:
    """JointState layout: effort = thrust, velocity = speed, position = position."""
    store = typestore()
    streams: dict[str, _Stream] = {s: _stream() for s in SIGNALS}
    fields = {tp.THRUST: "effort", tp.SPEED: "velocity", tp.POSITION: "position"}
    seen: set[str] = set()
    conns = [c for c in reader.connections if c.topic == topic]
    stopped = False
    start, stop, lo, hi = window or _WHOLE
    for conn, _, data in reader.messages(connections=conns, start=start, stop=stop):
        msg: Any = store.deserialize_cdr(data, conn.msgtype)
        k = _joint_index(list(msg.name), joint_name, seen)
        stamp = _stamp_ns(msg)
        if k is None or not lo <= stamp < hi:
            continue
        for signal, field in fields.items():
            arr = getattr(msg, field)
            if len(arr) > k:
                streams[signal][0].append(stamp)
                streams[signal][1].append(float(arr[k]))
        if _enough({s: streams[s] for s in (tp.THRUST, tp.POSITION)}, until):
            stopped = True
            break
    if joint_name is None and len(seen) > 1:
        raise BagError(f"{path}: {topic} carries joints {', '.join(sorted(seen))}; say which "
                       f"is the axis, e.g. --joint {sorted(seen)[0]} (API: joint=)")
    if not streams[tp.POSITION][0]:
        what = f"joint '{joint_name}'" if joint_name else "a single joint"
        names = ", ".join(sorted(seen)) or "none"
        raise BagError(f"{path}: no {what} with positions on {topic} (joints: {names})")
    if not streams[tp.THRUST][0]:
        raise BagError(f"{path}: {topic} carries no effort (thrust) for the joint")
    return streams, stopped


def _seconds(stream: _Stream) -> tuple[np.ndarray[Any, np.dtype[np.float64]],
                                        np.ndarray[Any, np.dtype[np.float64]]]:
    return (np.frombuffer(stream[0], dtype=np.int64) / 1e9,
            np.frombuffer(stream[1], dtype=np.float64))


def _nonfinite(streams: dict[str, _Stream], topics: dict[str, str],
               ) -> tuple[tuple[str, str, float, int, float], ...]:
    """Where the non-finite samples are (signal, topic, stamp s, message index, value)."""
    out: list[tuple[str, str, float, int, float]] = []
    for signal, (stamps, values) in streams.items():
        v = np.frombuffer(values, dtype=np.float64)
        for i in np.flatnonzero(~np.isfinite(v))[:MAX_NONFINITE_LISTED]:
            out.append((signal, topics.get(signal, signal), stamps[int(i)] / 1e9, int(i),
                        float(v[i])))
    return tuple(sorted(out, key=lambda x: x[2])[:MAX_NONFINITE_LISTED])


def _common_horizon(streams: dict[str, _Stream]) -> dict[str, _Stream]:
    """A partial read cut by message count: keep what every stream reached (stamps up to
    the earliest of the streams' newest), so the messages one stream read past another's cut
    are not counted as unaligned (they were merely not read on the other topics)."""
    reached = [np.frombuffer(st, dtype=np.int64).max() for st, _ in streams.values() if st]
    if not reached:
        return streams
    horizon = min(reached)
    out: dict[str, _Stream] = {}
    for signal, (stamps_a, values_a) in streams.items():
        stamps = np.frombuffer(stamps_a, dtype=np.int64)
        keep = stamps <= horizon
        kept = _stream()
        kept[0].frombytes(stamps[keep].tobytes())
        kept[1].frombytes(np.frombuffer(values_a, dtype=np.float64)[keep].tobytes())
        out[signal] = kept
    return out


def _check_time_axis(path: Path, streams: dict[str, _Stream], topics: dict[str, str]) -> None:
    """Refuse a stream whose stamps repeat with other values: two samples claim one instant
    (a clock that jumped back, a stretch recorded twice), so no time axis holds them both. A
    message re-sent with its value is a duplicate (dropped); one that overtook another is
    re-sorted; neither repeats a stamp with another value."""
    for signal, (stamps_a, values_a) in streams.items():
        stamps = np.frombuffer(stamps_a, dtype=np.int64)
        if len(stamps) < 2 or stamps.min() == stamps.max():
            continue  # one stamp on every message: the aligner names an unstamped publisher
        values = np.frombuffer(values_a, dtype=np.float64)
        order = np.argsort(stamps, kind="stable")
        s, v = stamps[order], values[order]
        same = s[1:] == s[:-1]
        other = (v[1:] != v[:-1]) & ~(np.isnan(v[1:]) & np.isnan(v[:-1]))
        late = order[1:][same & other]  # the later received copy of each repeated stamp
        if not len(late):
            continue
        i = int(late.min())
        raise DataError(
            f"{path}: {len(late)} stamps on {topics.get(signal, signal)} repeat with other "
            f"values (at message {i} the stamps jump back from t = "
            f"{int(stamps[:i].max()) / 1e9:.6g} s to {stamps[i] / 1e9:.6g} s): two samples "
            "claim one instant, so the time axis is broken (a clock reset, or a stretch "
            "recorded twice); cut the recording at the jump or stamp it again")


def read_recording(
    path: str | Path,
    *,
    namespace: str | None = None,
    tolerance_s: float | None = None,
    joint_name: str | None = None,
    until_sample: int | None = None,
    window: Window | None = None,
) -> LoadedRecording:
    """Read and align the input signals of a bag (``header.stamp``, not receive time).

    ``namespace`` None auto-detects the ``<ns>/thrust`` + ``<ns>/position`` (+ ``<ns>/speed``)
    topics, or a single ``sensor_msgs/JointState`` topic (``namespace`` may also name that
    topic). Speed absent -> derived from position and marked. See :func:`align_streams`.

    ``until_sample``: the caller needs samples before this index only; reading stops
    :data:`READ_MARGIN` messages per stream after it, so a short window early in a long
    recording costs what the window costs, not what the recording does (``complete`` is
    then False and the alignment counts cover the part read).

    ``window``: read only the messages logged within its log times (either may be None)
    whose ``header.stamp`` lies within its stamps: one span of a long recording
    (:mod:`.spans`).
    """
    path = Path(path)
    with open_reader(path) as reader:
        got = _read_streams(path, reader, namespace, joint_name, until_sample, window)
    return _aligned(path, got, tolerance_s)


#: What :func:`_read_streams` read: streams, whether it stopped early, layout, topics found,
#: topics used, the bag's custom metadata.
_Read = tuple[dict[str, _Stream], bool, dict[str, str], dict[str, str], dict[str, str],
              dict[str, Any]]


def _read_streams(path: Path, reader: Any, namespace: str | None, joint_name: str | None,
                  until_sample: int | None, window: Window | None) -> _Read:
    """The input streams of the opened bag (read within :func:`.common.reading`)."""
    found = {c.topic: c.msgtype for c in reader.connections}
    layout = _choose_layout(path, found, namespace)
    if "joint_state" in layout:
        streams, stopped = _read_joint(path, reader, layout["joint_state"], joint_name,
                                       until_sample, window)
        used = {layout["joint_state"]: tp.JOINT_STATE_TYPE}
    else:
        if joint_name is not None:
            raise BagError(f"{path}: a joint was named ('{joint_name}') but the inputs are "
                           f"{', '.join(layout.values())}, not a JointState topic")
        streams, stopped = _read_triple(reader, layout, until_sample, window)
        used = {topic: found[topic] for topic in layout.values()}
        empty = [layout[s] for s in (tp.THRUST, tp.POSITION) if not streams[s][0]]
        if empty:
            raise BagError(f"{path}: no messages on {' and '.join(empty)} (empty recording)")
    custom = getattr(reader.storage.metadata, "custom", None) or {}
    return streams, stopped, layout, found, used, custom


def _aligned(path: Path, got: _Read, tolerance_s: float | None) -> LoadedRecording:
    """The streams read aligned on one time axis (:func:`align_streams`)."""
    streams, stopped, layout, found, used, custom = got
    complete = not stopped
    if stopped:
        streams = _common_horizon(streams)
    topics = {s: layout.get(s, layout.get("joint_state", s)) for s in SIGNALS}
    nonfinite = _nonfinite(streams, topics)
    _check_time_axis(path, streams, topics)
    speed = _seconds(streams[tp.SPEED]) if tp.SPEED in streams and streams[tp.SPEED][0] else None
    try:
        rec, report = align_streams(_seconds(streams[tp.THRUST]), speed,
                                    _seconds(streams[tp.POSITION]), tolerance_s=tolerance_s,
                                    source=str(path))
    except DataError as exc:
        hint = ""
        if len(set(streams[tp.POSITION][0])) <= 1:
            hint = "; header.stamp is the same on every position message (publisher not stamping?)"
        raise DataError(f"{path}: {exc}{hint}") from exc
    # The wire carries integer nanoseconds: read the rate from them (500 Hz, not 499.9999...).
    ns = np.round(rec.t * 1e9).astype(np.int64)
    rate = 1e9 / robust_period(ns)
    meta = {k: str(v) for k, v in custom.items()}
    meta.update({"bag": str(path), "input_topics": ",".join(sorted(used))})
    rec = replace(rec, meta=meta, sample_rate_hz=rate)
    return LoadedRecording(recording=rec, report=report, topics=found, nonfinite=nonfinite,
                           complete=complete)


def check_ranges_finite(loaded: LoadedRecording, ranges: dict[str, tuple[int, int]],
                        lag: int) -> None:
    """Refuse a range (with its ``lag`` samples before it) over a non-finite sample, naming
    the sample: its signal, value, stamp and message on its topic."""
    t = loaded.recording.t
    if not loaded.nonfinite or len(t) == 0:
        return
    half = 0.5 / loaded.recording.sample_rate_hz
    for label, (start, stop) in ranges.items():
        if stop > len(t):
            continue  # outside the recording: said by the fit's own checks
        lo, hi = max(0, start - lag), stop - 1
        inside = [x for x in loaded.nonfinite if t[lo] - half <= x[2] <= t[hi] + half]
        if inside:
            signal, topic, stamp, index, value = inside[0]
            more = f" and {len(inside) - 1} more" if len(inside) > 1 else ""
            raise DataError(
                f"{label} range {start}:{stop} (lags from sample {lo}, t = {t[lo]:.3f} to "
                f"{t[hi]:.3f} s) holds a non-finite {signal} sample ({value}) at t = "
                f"{stamp:.6g} s, message {index} on {topic}{more}; non-finite samples are "
                "dropped on reading and cannot be fitted: choose a range without it")


def check_all_finite(loaded: LoadedRecording, what: str, use: str) -> None:
    """Refuse a recording used whole (``use``: by what) that held a non-finite sample,
    naming the first: dropped on reading, it would leave a hole in the sampling grid."""
    if not loaded.nonfinite:
        return
    signal, topic, stamp, index, value = loaded.nonfinite[0]
    more = f" and {len(loaded.nonfinite) - 1} more" if len(loaded.nonfinite) > 1 else ""
    raise DataError(f"{what} holds a non-finite {signal} sample ({value}) at t = {stamp:.6g} s, "
                    f"message {index} on {topic}{more}: {use} uses the whole recording, so "
                    "every sample must be finite; cut the recording before it or repair it")
