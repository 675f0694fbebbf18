"""Writing whole recordings (the three input topics) as rosbag2 bags."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import Writer

from .. import topics as tp
from ..core.errors import BagError, PmsmSysidError
from ..core.recording.signals import FloatArray, Recording
from .cdr import encode_stamped
from .common import (
    CUSTOM_PREFIX,
    DEFAULT_QOS,
    FRAME_ID,
    SPEED_DERIVED_NOTE,
    connection_args,
    storage_plugin,
)
from .mcap_block import append_block, block_writer


def _stamps_ns(t: FloatArray) -> np.ndarray[Any, np.dtype[np.int64]]:
    ns = np.round(np.asarray(t, dtype=np.float64) * 1e9)
    if not np.all(np.isfinite(ns)) or np.any(ns < 0) or np.any(ns >= 2**31 * 1e9):
        raise BagError("stamps must be finite seconds in [0, 2**31) (builtin_interfaces/Time) "
                       "to be written to a bag")
    return ns.astype(np.int64)


def _custom_data(rec: Recording, extra: Mapping[str, str] | None) -> dict[str, str]:
    data = {
        CUSTOM_PREFIX + "sample_rate_hz": repr(float(rec.sample_rate_hz)),
        CUSTOM_PREFIX + "speed": SPEED_DERIVED_NOTE if rec.speed_derived else "measured",
    }
    if rec.source:
        data[CUSTOM_PREFIX + "source"] = rec.source
    for key, value in {**rec.meta, **(extra or {})}.items():
        data[CUSTOM_PREFIX + str(key)] = str(value)
    return data


#: Samples converted to Python numbers at a time while writing (bounded extra memory).
WRITE_BLOCK = 1 << 16


class RecordingWriter:
    """The three input topics of a recording, written a block of samples at a time."""

    def __init__(self, writer: Writer, conns: list[tuple[Any, str, str]]) -> None:
        self._writer = writer
        self._conns = conns  # (connection, msgtype, signal name or extra topic name)

    def write(self, rec: Recording, extra_points: Mapping[str, FloatArray] | None = None,
              ) -> None:
        """Append ``rec``'s samples (and the extra topics' values for them)."""
        ns = _stamps_ns(rec.t)
        extra = extra_points or {}
        for name, values in extra.items():
            if len(values) != len(ns):
                raise BagError(f"extra topic '{name}' has {len(values)} values, "
                               f"recording {len(ns)}")
        arrays = [extra[name] if name in extra else rec.signal(name)
                  for _, _, name in self._conns]
        storage = block_writer(self._writer)
        for start in range(0, len(ns), WRITE_BLOCK):
            stop = start + WRITE_BLOCK
            if storage is not None:
                append_block(self._writer, storage, [c for c, _, _ in self._conns],
                             [t for _, t, _ in self._conns], FRAME_ID, ns[start:stop],
                             [np.asarray(a[start:stop], dtype=np.float64) for a in arrays])
                continue
            columns = [(conn, msgtype, np.asarray(values[start:stop], dtype=np.float64).tolist())
                       for (conn, msgtype, _), values in zip(self._conns, arrays, strict=True)]
            for k, stamp in enumerate(ns[start:stop].tolist()):
                for conn, msgtype, values in columns:
                    self._writer.write(conn, stamp,
                                       encode_stamped(msgtype, stamp, FRAME_ID, values[k]))


@contextmanager
def recording_writer(
    path: str | Path,
    like: Recording,
    *,
    namespace: str = tp.DEFAULT_NAMESPACE,
    storage: str = "mcap",
    extra_topics: Sequence[str] = (),
    custom_data: Mapping[str, str] | None = None,
) -> Iterator[RecordingWriter]:
    """A bag at ``path`` for recordings like ``like`` (its rate, metadata, speed topic or
    not), written block by block with :meth:`RecordingWriter.write`."""
    path = Path(path)
    if path.exists():
        raise BagError(f"{path} exists already, not overwriting")
    plugin = storage_plugin(storage)
    signals: list[tuple[str, str, str]] = []  # topic, type, signal or extra name
    for name in ("thrust", "speed", "position"):
        if name == "speed" and like.speed_derived:
            continue
        signals.append((tp.input_topic(namespace, name), tp.INPUT_TYPES[name], name))
    signals += [(tp.input_topic(namespace, name), tp.POSITION_TYPE, name)
                for name in extra_topics]
    try:
        with Writer(path, version=9, storage_plugin=plugin) as writer:
            conns = []
            for topic, msgtype, name in signals:
                msgdef, digest = connection_args(msgtype)
                conns.append((writer.add_connection(topic, msgtype, msgdef=msgdef,
                                                    rihs01=digest,
                                                    offered_qos_profiles=[DEFAULT_QOS]),
                              msgtype, name))
            for key, value in _custom_data(like, custom_data).items():
                writer.set_custom_data(key, value)
            yield RecordingWriter(writer, conns)
    except PmsmSysidError:
        raise
    except Exception as exc:
        raise BagError(f"{path}: cannot write bag ({type(exc).__name__}: {exc})") from exc


def write_recording(
    path: str | Path,
    rec: Recording,
    *,
    namespace: str = tp.DEFAULT_NAMESPACE,
    storage: str = "mcap",
    extra_points: Mapping[str, FloatArray] | None = None,
    custom_data: Mapping[str, str] | None = None,
) -> None:
    """Write ``rec`` as the standard three topics, all stamped ``header.stamp = rec.t``.

    Receive time = stamp. A recording whose speed is derived gets no speed topic (readers
    derive it again; the bag's ``custom_data`` says so). ``extra_points`` adds one
    ``PointStamped`` topic ``<namespace>/<name>`` per entry (same stamps, e.g. a reference
    position). Refuses to overwrite an existing path. Samples are converted
    ``WRITE_BLOCK`` at a time: the memory beyond ``rec`` stays bounded.
    """
    extra = dict(extra_points or {})
    if Path(path).exists():
        raise BagError(f"{path} exists already, not overwriting")
    _stamps_ns(rec.t)  # refuse bad input before creating anything
    for name, values in extra.items():
        if len(values) != len(rec):
            raise BagError(f"extra topic '{name}' has {len(values)} values, recording {len(rec)}")
    with recording_writer(path, rec, namespace=namespace, storage=storage,
                          extra_topics=tuple(extra), custom_data=custom_data) as out:
        out.write(rec, extra)
