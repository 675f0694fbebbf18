"""Shared pieces of the rosbag2 I/O package: typestore, QoS, errors, an opened reader."""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime as _QosTime
from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ..core.errors import BagError, PmsmSysidError
from ..core.recording.align import AlignReport
from ..core.recording.signals import Recording

FRAME_ID = "pmsm"
MSG_PACKAGE = "pmsm_sysid/msg"
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
CUSTOM_PREFIX = "pmsm_sysid."
SPEED_DERIVED_NOTE = (
    "absent: derived on reading from position by the causal backward difference"
)

# rosbag2 writes "infinite" durations like this in metadata.yaml (Jazzy).
_INF = _QosTime(sec=9223372036, nsec=854775807)
#: Offered QoS written for the project's topics: rclpy's default publisher profile.
DEFAULT_QOS = Qos(
    history=QosHistory.KEEP_LAST, depth=10, reliability=QosReliability.RELIABLE,
    durability=QosDurability.VOLATILE, deadline=_INF, lifespan=_INF,
    liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=_INF,
    avoid_ros_namespace_conventions=False,
)


class RawMessage(NamedTuple):
    """One serialized message as logged: CDR bytes exactly as stored."""

    topic: str
    msgtype: str
    timestamp_ns: int
    data: bytes


@dataclass(frozen=True)
class LoadedRecording:
    """A recording read from a bag, how it was aligned, and the topics found (topic -> type)."""

    recording: Recording
    report: AlignReport
    topics: dict[str, str]
    #: Non-finite samples dropped on reading: (signal, topic, stamp in s, message index, value),
    #: the first :data:`MAX_NONFINITE_LISTED` of them.
    nonfinite: tuple[tuple[str, str, float, int, float], ...] = ()
    #: False when reading stopped early because the samples asked for were read
    #: (``read_recording(until_sample=...)``): the counts then cover the part read.
    complete: bool = True


#: How many non-finite samples a loaded recording lists by position.
MAX_NONFINITE_LISTED = 100


# --------------------------------------------------------------------------- typestore


def schema_dir() -> Path:
    """Directory holding the package's ``msg_schemas/*.msg`` (source tree or installed share)."""
    here = Path(__file__).resolve().parent
    candidates = [here.parents[1] / "msg_schemas"]
    if len(here.parents) > 4:  # <prefix>/lib/pythonX.Y/site-packages/pmsm_sysid/bagio
        candidates.append(here.parents[4] / "share" / "pmsm_sysid" / "msg_schemas")
    candidates.append(Path(sys.prefix) / "share" / "pmsm_sysid" / "msg_schemas")
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / "share" / "pmsm_sysid" / "msg_schemas")
    for cand in candidates:
        if any(cand.glob("*.msg")):
            return cand
    raise BagError("msg_schemas/*.msg not found beside the package or in share/pmsm_sysid")


@functools.lru_cache(maxsize=1)
def typestore() -> Typestore:
    """ROS 2 Jazzy types plus the package's own ``pmsm_sysid/msg/<Name>`` schemas."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for path in sorted(schema_dir().glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"{MSG_PACKAGE}/{path.stem}"))
    store.register(types)
    return store


def connection_args(msgtype: str) -> tuple[str, str]:
    """(message definition, RIHS01 hash) of ``msgtype``; BagError if the type is unknown."""
    store = typestore()
    if msgtype not in store.fielddefs:
        raise BagError(f"unknown message type '{msgtype}' (not in ROS 2 Jazzy or msg_schemas)")
    msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
    return msgdef, store.hash_rihs01(msgtype)


def storage_plugin(storage: str) -> StoragePlugin:
    """The rosbags plugin for a storage name; BagError for anything but mcap/sqlite3."""
    try:
        return STORAGES[storage]
    except KeyError:
        raise BagError(f"unknown storage '{storage}' (expected mcap or sqlite3)") from None


# --------------------------------------------------------------------------- reading


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__  # one line, always
    return text[:-1] if text.endswith(".") else text


@contextmanager
def open_reader(path: str | Path) -> Iterator[Any]:
    """An open ``rosbags.rosbag2.Reader``; every failure becomes one-line :class:`BagError`."""
    with opened(path) as reader, reading(Path(path)):
        yield reader


@contextmanager
def opened(path: str | Path) -> Iterator[Any]:
    """An open ``rosbags.rosbag2.Reader`` (a failure to open becomes one-line
    :class:`BagError`): read it within :func:`reading`."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    _precheck(path)
    try:
        reader = Reader(path)
        reader.open()
    except PermissionError as exc:
        raise BagError(f"{path}: permission denied ({exc.filename or path})") from exc
    except Exception as exc:
        raise BagError(f"{path}: {_explain(path, exc)}") from exc
    try:
        yield reader
    finally:
        with suppress(Exception):  # closing a broken reader must not hide the cause
            reader.close()


@contextmanager
def reading(path: Path) -> Iterator[None]:
    """Reading an opened bag: every failure becomes one-line :class:`BagError`."""
    try:
        yield
    except PmsmSysidError:
        raise
    except Exception as exc:
        raise BagError(f"{path}: storage is corrupt or truncated ({_reason(exc)})") from exc


def _precheck(path: Path) -> None:
    try:
        exists, is_dir, is_file = path.exists(), path.is_dir(), path.is_file()
    except PermissionError as exc:  # a parent directory cannot be searched
        raise BagError(f"{path}: permission denied ({exc.filename or path})") from exc
    if not exists:
        raise BagError(f"{path}: no such bag (directory or .mcap/.db3 file)")
    if is_dir and not os.access(path, os.R_OK | os.X_OK):
        raise BagError(f"{path}: permission denied")
    if is_file and path.suffix not in (".mcap", ".db3"):
        raise BagError(f"{path}: not a rosbag2 directory or .mcap/.db3 file")
    stores = ([p for p in path.iterdir() if p.suffix in (".mcap", ".db3")] if is_dir
              else [path] if is_file else [])
    empty = sorted(p.name for p in stores if p.is_file() and p.stat().st_size == 0)
    if empty:
        raise BagError(f"{path}: storage file {', '.join(empty)} is empty (0 bytes): the "
                       "recording holds no messages (was it killed before its first write?)")


def _explain(path: Path, exc: Exception) -> str:
    """Turn a rosbags open error into a sentence naming what is wrong."""
    text = _reason(exc)
    if isinstance(exc, FileNotFoundError) and "metadata" in text:
        stores = sorted(p.name for p in path.glob("*") if p.suffix in (".mcap", ".db3"))
        if stores:
            return (f"no metadata.yaml beside {', '.join(stores)}: not finalised; "
                    "repair it with `python -m pmsm_sysid.bagio repair BAG`")
        return "not a rosbag2 directory (no metadata.yaml)"
    if "permission denied" in text.lower():
        return f"permission denied ({text})"
    if "files are missing" in text:
        return f"storage file(s) listed in metadata.yaml are missing ({text})"
    if "Storage plugin" in text:
        return f"unknown storage plugin in metadata.yaml ({text}); expected mcap or sqlite3"
    if "metadata" in text.lower() or "YAML" in text:
        return f"corrupt metadata.yaml ({text})"
    hint = ""
    if "end magic" in text or "footer" in text.lower():
        hint = "; if its recording was killed, `python -m pmsm_sysid.bagio repair BAG` salvages it"
    return f"cannot open storage: corrupt, truncated or not a bag ({text}){hint}"


