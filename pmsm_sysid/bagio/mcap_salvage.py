"""Salvage an ``.mcap`` whose writer was killed: keep every complete chunk, rewrite the file.

A killed ``rosbags`` MCAP writer leaves the header and the chunks already written (the
:class:`~pmsm_sysid.bagio.BagRecorder` writes one per flush) but no summary and no footer,
which every reader requires. This scans the records in file order (MCAP spec: opcode u8,
length u64, body), stops at the first incomplete one, and writes the schemas, channels and
messages of the complete chunks into a new ``.mcap`` with ``rosbags``. The damaged file is
kept beside it as ``<name>.mcap.damaged``.
"""

from __future__ import annotations

import shutil
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import decompress, get_qos

from ..core.errors import BagError
from .common import typestore

MAGIC = b"\x89MCAP0\r\n"
OP_CHUNK, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x06, 0x03, 0x04, 0x05


@dataclass
class _Scan:
    schemas: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> name, msgdef
    channels: dict[int, tuple[str, int, bytes]] = field(default_factory=dict)  # topic, schema
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)  # channel, time, data


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", buf, pos)
    return buf[pos + 4:pos + 4 + n].decode(), pos + 4 + n


def _records(buf: bytes, pos: int) -> list[tuple[int, bytes]]:
    """Complete (opcode, body) records from ``pos``; stops at the first incomplete one."""
    out = []
    while pos + 9 <= len(buf):
        op, size = buf[pos], struct.unpack_from("<Q", buf, pos + 1)[0]
        if pos + 9 + size > len(buf):
            break
        out.append((op, buf[pos + 9:pos + 9 + size]))
        pos += 9 + size
    return out


def _chunk(body: bytes, scan: _Scan) -> None:
    start_end_size = struct.unpack_from("<QQQI", body, 0)
    compression, pos = _string(body, 28)
    (length,) = struct.unpack_from("<Q", body, pos)
    raw = decompress(body[pos + 8:pos + 8 + length], compression, start_end_size[2],
                     start_end_size[3])
    for op, rec in _records(raw, 0):
        if op == OP_SCHEMA:
            (sid,) = struct.unpack_from("<H", rec, 0)
            name, p = _string(rec, 2)
            _, p = _string(rec, p)  # encoding (ros2msg)
            (n,) = struct.unpack_from("<I", rec, p)
            scan.schemas[sid] = (name, rec[p + 4:p + 4 + n].decode())
        elif op == OP_CHANNEL:
            cid, sid = struct.unpack_from("<HH", rec, 0)
            topic, p = _string(rec, 4)
            _, p = _string(rec, p)  # message encoding (cdr)
            (n,) = struct.unpack_from("<I", rec, p)
            scan.channels[cid] = (topic, sid, rec[p + 4:p + 4 + n])
        elif op == OP_MESSAGE:
            cid, _, log_time = struct.unpack_from("<HIQ", rec, 0)
            scan.messages.append((cid, log_time, rec[22:]))


def scan_mcap(path: Path) -> _Scan:
    """Schemas, channels and messages of every complete chunk of an MCAP file."""
    buf = path.read_bytes()
    if not buf.startswith(MAGIC):
        raise BagError(f"{path}: not an MCAP file")
    scan = _Scan()
    for op, body in _records(buf, len(MAGIC)):
        if op == OP_CHUNK:
            try:
                _chunk(body, scan)
            except Exception as exc:
                raise BagError(f"{path}: damaged chunk ({exc})") from exc
    return scan


def _old_hashes(bag: Path) -> tuple[dict[str, str], dict[str, str] | None]:
    try:
        info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        hashes = {t["topic_metadata"]["name"]: t["topic_metadata"]["type_description_hash"]
                  for t in info["topics_with_message_count"]}
        return hashes, info.get("custom_data")
    except Exception:
        return {}, None


def salvage_mcap(bag: Path, mcap: Path) -> int:
    """Rewrite ``mcap`` from its complete chunks and regenerate metadata; message count."""
    scan = scan_mcap(mcap)
    hashes, custom = _old_hashes(bag)
    tmp = bag / ".salvage" / bag.name
    shutil.rmtree(tmp.parent, ignore_errors=True)
    conns: dict[int, Any] = {}
    with Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for cid, (topic, sid, meta) in sorted(scan.channels.items()):
            name, msgdef = scan.schemas[sid]
            digest = hashes.get(topic) or (typestore().hash_rihs01(name)
                                           if name in typestore().fielddefs else "")
            if not digest:
                raise BagError(f"{mcap}: no type hash for {name} on {topic}")
            conns[cid] = writer.add_connection(topic, name, msgdef=msgdef, rihs01=digest,
                                               offered_qos_profiles=get_qos(meta))
        for key, value in (custom or {}).items():
            writer.set_custom_data(str(key), str(value))
        for cid, log_time, data in sorted(scan.messages, key=lambda m: m[1]):
            writer.write(conns[cid], log_time, data)
    mcap.rename(mcap.with_name(mcap.name + ".damaged"))
    (tmp / f"{bag.name}.mcap").rename(mcap)
    meta = yaml.safe_load((tmp / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info["relative_file_paths"] = [mcap.name]
    info["files"][0]["path"] = mcap.name
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta, default_flow_style=False))
    shutil.rmtree(tmp.parent)
    return len(scan.messages)
