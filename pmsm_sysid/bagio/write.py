"""Writing whole recordings (the three input topics) as rosbag2 bags."""

from __future__ import annotations

from collections.abc import Mapping
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
    position). Refuses to overwrite an existing path.
    """
    path = Path(path)
    if path.exists():
        raise BagError(f"{path} exists already, not overwriting")
    plugin = storage_plugin(storage)
    ns = _stamps_ns(rec.t)
    signals: list[tuple[str, str, FloatArray]] = []  # topic, type, values
    for name in ("thrust", "speed", "position"):
        if name == "speed" and rec.speed_derived:
            continue
        signals.append((tp.input_topic(namespace, name), tp.INPUT_TYPES[name], rec.signal(name)))
    for name, values in (extra_points or {}).items():
        if len(values) != len(ns):
            raise BagError(f"extra topic '{name}' has {len(values)} values, recording {len(ns)}")
        signals.append((tp.input_topic(namespace, name), tp.POSITION_TYPE,
                        np.asarray(values, dtype=np.float64)))
    try:
        with Writer(path, version=9, storage_plugin=plugin) as writer:
            conns = []
            for topic, msgtype, _ in signals:
                msgdef, digest = connection_args(msgtype)
                conns.append(writer.add_connection(topic, msgtype, msgdef=msgdef, rihs01=digest,
                                                   offered_qos_profiles=[DEFAULT_QOS]))
            for key, value in _custom_data(rec, custom_data).items():
                writer.set_custom_data(key, value)
            columns = [(conn, msgtype, values.tolist())
                       for conn, (_, msgtype, values) in zip(conns, signals, strict=True)]
            for k, stamp in enumerate(ns.tolist()):
                for conn, msgtype, values in columns:
                    writer.write(conn, stamp, encode_stamped(msgtype, stamp, FRAME_ID, values[k]))
    except PmsmSysidError:
        raise
    except Exception as exc:
        raise BagError(f"{path}: cannot write bag ({type(exc).__name__}: {exc})") from exc
