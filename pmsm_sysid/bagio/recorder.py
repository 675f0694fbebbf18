"""Streaming recording (``record``, ``run --record``) that survives being killed.

Crash behaviour of ``rosbags`` as shipped (0.11.9), which this module works around:

* sqlite3: every message is an INSERT inside one transaction that is committed only by
  ``close()``; ``metadata.yaml`` is written only by ``close()``. A killed process leaves an
  unreadable bag (no metadata) whose rows were never committed.
* mcap: messages are buffered in a 1 MiB in-memory chunk; the summary and footer are
  written by ``close()``. A killed process leaves a file without footer, which readers reject.

:class:`BagRecorder` therefore defaults to **sqlite3** in WAL mode and, every
``flush_interval_s`` (checked on each write, or on :meth:`flush`), commits, checkpoints the
WAL into the ``.db3`` and rewrites ``metadata.yaml`` atomically to match what is committed.
Guarantee: a hard kill (SIGKILL, a crash of the process) loses at most the messages
written since the last flush; the bag stays readable as-is by ``rosbags``/``ros2 bag``, and
:func:`repair` rebuilds ``metadata.yaml`` from the database in the rare case the kill hit a
flush. SIGINT/SIGTERM turned into an exception or normal exit (rclpy does this; otherwise
:func:`sigterm_as_exit`) finalise the bag through ``close()`` (context manager, ``atexit``).
With ``storage="mcap"`` the pending chunk is written to disk at each flush too, but a killed
``.mcap`` lacks its footer: readers refuse it until :func:`repair` rewrites it from its
complete chunks (same loss bound).
"""

from __future__ import annotations

import atexit
import signal
import sqlite3
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.metadata import dump_qos_v9

from ..core.errors import BagError, PmsmSysidError
from .common import DEFAULT_QOS, connection_args, storage_plugin

TopicRow = tuple[str, str, str, Any, str, int]  # name, type, format, qos list, hash, count


def metadata_dict(storage_id: str, file_name: str, rows: list[TopicRow], start: int,
                  end: int, custom: dict[str, str] | None = None) -> dict[str, Any]:
    """``metadata.yaml`` content (rosbag2 version 9), as ``rosbags`` writes it on close."""
    count = sum(r[5] for r in rows)
    start = start if count else 0
    duration = max(0, end - start) if count else 0
    return {"rosbag2_bagfile_information": {
        "version": 9, "storage_identifier": storage_id, "relative_file_paths": [file_name],
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start}, "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": n, "type": t, "serialization_format": f,
                                "offered_qos_profiles": q, "type_description_hash": h},
             "message_count": c} for n, t, f, q, h, c in rows],
        "compression_format": "", "compression_mode": "",
        "files": [{"path": file_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": custom or None, "ros_distro": "rosbags",
    }}


def write_metadata(bag: Path, meta: dict[str, Any]) -> None:
    """Write ``bag/metadata.yaml`` atomically (temp file + rename)."""
    tmp = bag / "metadata.yaml.tmp"
    tmp.write_text(yaml.safe_dump(meta, default_flow_style=False, sort_keys=False))
    tmp.replace(bag / "metadata.yaml")


class BagRecorder:
    """Write serialized messages as received into a new rosbag2; see the module docstring."""

    def __init__(self, path: str | Path, *, storage: str = "sqlite3",
                 flush_interval_s: float = 1.0) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already, not overwriting")
        if not flush_interval_s > 0:
            raise BagError(f"flush interval must be > 0 s, got {flush_interval_s}")
        self.storage = storage
        self.flush_interval_s = float(flush_interval_s)
        plugin = storage_plugin(storage)
        self._writer = Writer(self.path, version=9, storage_plugin=plugin)
        try:
            self._writer.open()
        except Exception as exc:
            raise BagError(f"{self.path}: cannot create bag ({exc})") from exc
        self._sqlite: sqlite3.Connection | None = None
        if plugin == StoragePlugin.SQLITE3:
            self._sqlite = self._writer.storage.conn  # type: ignore[union-attr]
            self._sqlite.commit()
            self._sqlite.execute("PRAGMA journal_mode=WAL")
        self._conns: dict[str, Connection] = {}
        # re-entrant: a Ctrl-C that lands between acquiring and entering a `with` block leaks
        # the lock in the main thread; close() in that same thread must still get it
        self._lock = threading.RLock()
        self._closed = False
        self._last_flush = time.monotonic()
        self.messages_written = 0
        #: messages durable on disk and listed in metadata.yaml (as of the last flush)
        self.messages_flushed = 0
        atexit.register(self.close)
        with self._lock:
            self._flush_locked()

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic before writing to it (same topic + same type again is a no-op)."""
        with self._lock:
            self._check_open()
            if topic in self._conns:
                if self._conns[topic].msgtype != msgtype:
                    raise BagError(f"{topic} already recorded as {self._conns[topic].msgtype}, "
                                   f"not {msgtype}")
                return
            msgdef, digest = connection_args(msgtype)
            self._conns[topic] = self._writer.add_connection(
                topic, msgtype, msgdef=msgdef, rihs01=digest, offered_qos_profiles=[DEFAULT_QOS])
            self._flush_locked()

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> None:
        """Store one message (CDR bytes, kept bit-for-bit) with its receive time."""
        with self._lock:
            self._check_open()
            conn = self._conns.get(topic)
            if conn is None:
                raise BagError(f"write to {topic} before add_topic({topic!r}, ...)")
            self._writer.write(conn, int(timestamp_ns), data)
            self.messages_written += 1
            if time.monotonic() - self._last_flush >= self.flush_interval_s:
                self._flush_locked()

    def flush(self) -> None:
        """Make everything written so far durable and readable now."""
        with self._lock:
            if not self._closed:
                self._flush_locked()

    def close(self) -> None:
        """Finalise the bag (full metadata, index); idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            atexit.unregister(self.close)
            try:
                if self._sqlite is not None:
                    self._sqlite.commit()
                    self._sqlite.execute("PRAGMA journal_mode=DELETE")
                self._writer.close()
                self.messages_flushed = self.messages_written
            except Exception as exc:
                raise BagError(f"{self.path}: cannot finalise bag ({exc})") from exc

    def __enter__(self) -> BagRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f"{self.path}: recorder is closed")

    def _flush_locked(self) -> None:
        storage: Any = self._writer.storage
        try:
            if self._sqlite is not None:
                self._sqlite.commit()
                self._sqlite.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            elif storage.chunk.msgs:
                storage.close_chunk()
                storage.bio.flush()
            write_metadata(self.path, self._metadata())
            self.messages_flushed = self.messages_written
        except PmsmSysidError:
            raise
        except Exception as exc:
            raise BagError(f"{self.path}: cannot flush bag ({exc})") from exc
        self._last_flush = time.monotonic()

    def _metadata(self) -> dict[str, Any]:
        w = self._writer
        rows: list[TopicRow] = [
            (c.topic, c.msgtype, "cdr", dump_qos_v9(list(c.ext.offered_qos_profiles)),  # type: ignore[union-attr]
             c.digest, w.counts[c.id]) for c in w.connections]
        return metadata_dict(self.storage, w.storage.path.name, rows,  # type: ignore[union-attr]
                             w.min_timestamp, w.max_timestamp)


@contextmanager
def sigterm_as_exit() -> Iterator[None]:
    """Within the block SIGTERM raises ``SystemExit(143)`` (as SIGINT raises
    ``KeyboardInterrupt``), so ``with BagRecorder(...)`` blocks unwind and finalise the bag.
    For programs that do not let rclpy handle SIGTERM; main thread only."""
    def _exit(signum: int, frame: object) -> None:
        sys.exit(128 + signum)

    previous = signal.signal(signal.SIGTERM, _exit)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _old_custom(bag: Path) -> dict[str, str] | None:
    try:
        info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        custom = info.get("custom_data")
        return {str(k): str(v) for k, v in custom.items()} if custom else None
    except Exception:
        return None


def repair(path: str | Path) -> int:
    """Make a killed bag readable again; returns the number of messages recovered.

    sqlite3: rebuild ``metadata.yaml`` from the database (opening it read-write lets SQLite
    roll back a half-written transaction and replay a committed WAL, so every committed
    message is kept). mcap: rewrite the file from its complete chunks
    (:func:`~.mcap_salvage.salvage_mcap`; the damaged file is kept as ``*.mcap.damaged``).
    """
    bag = Path(path)
    if not bag.is_dir():
        raise BagError(f"{bag}: not a bag directory")
    dbs = sorted(bag.glob("*.db3"))
    mcaps = sorted(bag.glob("*.mcap"))
    if len(mcaps) == 1 and not dbs:
        from .mcap_salvage import salvage_mcap

        return salvage_mcap(bag, mcaps[0])
    if len(dbs) != 1 or mcaps:
        raise BagError(f"{bag}: repair needs exactly one .db3 or one .mcap file, found "
                       f"{len(dbs)} .db3 and {len(mcaps)} .mcap")
    try:
        con = sqlite3.connect(dbs[0])
        try:
            con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            con.execute("PRAGMA journal_mode=DELETE")
            topics = con.execute(
                "SELECT name, type, serialization_format, offered_qos_profiles, "
                "type_description_hash, (SELECT count(*) FROM messages m WHERE m.topic_id = t.id)"
                " FROM topics t ORDER BY t.id").fetchall()
            span = "SELECT MIN(timestamp), MAX(timestamp) FROM messages"
            start, end = con.execute(span).fetchone()
        finally:
            con.close()
    except sqlite3.Error as exc:
        raise BagError(f"{dbs[0]}: not a readable rosbag2 database ({exc})") from exc
    rows: list[TopicRow] = [(n, t, f, yaml.safe_load(q) or [], h, int(c))
                            for n, t, f, q, h, c in topics]
    write_metadata(bag, metadata_dict("sqlite3", dbs[0].name, rows, int(start or 0),
                                      int(end or 0), _old_custom(bag)))
    return sum(r[5] for r in rows)
