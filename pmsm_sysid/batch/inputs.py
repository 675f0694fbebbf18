"""The recordings of a fleet batch: paths, directories and glob patterns expanded to rosbag2
recordings, each recording's axes, and the content key that lets a batch resume.

A recording is a rosbag2 directory (``metadata.yaml`` and its ``.mcap``/``.db3`` files), a
directory holding ``.mcap``/``.db3`` files, or one such file. A directory that is none of
these is searched (recursively) for recordings. The **content key** of a recording is the
SHA-256 of its data files' bytes in name order (``metadata.yaml`` and all names left out):
a recording copied or renamed keeps its key, so a resumed batch skips it.
"""

from __future__ import annotations

import glob
import hashlib
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.errors import OptionError, PmsmSysidError

STORAGE_SUFFIXES = (".mcap", ".db3")
#: How a recording's axes are named: ``topic`` (the namespace, or the JointState joint name),
#: ``parent`` (the directory holding the recording, for fleets whose axes all record
#: under one namespace, e.g. ``axis07/2026-05-01/``).
AXIS_FROM = ("topic", "parent")


@dataclass(frozen=True)
class Unit:
    """The work of one row: one axis of one recording. ``axis`` is None when the recording
    could not be opened to list its axes (its row then says why)."""

    path: str
    namespace: str | None
    joint: str | None
    axis: str | None
    content: str

    def row_arguments(self) -> dict[str, Any]:
        """The keyword arguments of :func:`pmsm_sysid.api.fleet_row.recording_row` that
        say which axis of which recording this row is."""
        return {"namespace": self.namespace, "joint": self.joint, "axis": self.axis,
                "content_sha256": self.content}

    @property
    def key(self) -> str:
        """The row's identity: the recording's content and the axis read from it."""
        return f"{self.content}:{self.namespace or ''}:{self.joint or ''}"


def _is_recording(p: Path) -> bool:
    if p.is_file():
        return p.suffix in STORAGE_SUFFIXES
    if not p.is_dir():
        return False
    if (p / "metadata.yaml").exists():
        return True
    try:
        return any(c.suffix in STORAGE_SUFFIXES and c.is_file() for c in p.iterdir())
    except OSError:
        return False


def _walk(root: Path) -> Iterator[Path]:
    """Recordings under ``root`` in name order (a recording's own directory is not searched)."""
    if _is_recording(root):
        yield root
        return
    if not root.is_dir():
        return
    try:
        children = sorted(root.iterdir())
    except OSError as exc:
        raise OptionError(f"{root}: cannot list ({exc.strerror or exc})") from exc
    for child in children:  # a link to a recording is followed, a linked directory is not
        if _is_recording(child) and child.is_dir():
            yield child
        elif child.is_dir() and not child.is_symlink():
            yield from _walk(child)


def expand(arguments: Sequence[str]) -> list[Path]:
    """Every recording named by ``arguments`` (paths, directories, glob patterns), each
    once, in the order given (a storage file inside a recording directory also named is
    that recording). An argument that names no recording is an error."""
    if not arguments:
        raise OptionError("no recordings given (paths, directories or glob patterns)")
    found: list[Path] = []
    for arg in arguments:
        if glob.has_magic(arg):
            matches = [Path(m) for m in sorted(glob.glob(arg, recursive=True))]
        elif os.path.lexists(arg):
            matches = [Path(arg)]
        else:
            raise OptionError(f"{arg}: no such file or directory")
        mine = [r for m in matches for r in _walk(m)]
        if not mine:
            raise OptionError(f"{arg}: no recording found (a recording is a rosbag2 directory "
                              "or a .mcap/.db3 file)")
        found += mine
    dirs = {r.resolve() for r in found if r.is_dir()}
    seen: set[Path] = set()
    out: list[Path] = []
    for r in found:
        key = r.resolve()
        if key in seen or any(parent in dirs for parent in key.parents):
            continue
        seen.add(key)
        out.append(r)
    return out


def data_files(path: Path) -> list[Path]:
    """The files whose bytes are a recording's content (name order)."""
    if path.is_file():
        return [path]
    return sorted(c for c in path.iterdir() if c.is_file() and c.name != "metadata.yaml"
                  and not c.name.startswith("."))


def content_key(path: Path) -> str:
    """SHA-256 (hex) of the recording's data files, in name order; names left out. A
    recording that cannot be read gets a key of its path (its row will say why)."""
    digest = hashlib.sha256()
    try:
        for f in data_files(path):
            with open(f, "rb") as fh:
                digest.update(hashlib.file_digest(fh, "sha256").digest())
    except OSError:
        return "unreadable-" + hashlib.sha256(str(path.resolve()).encode()).hexdigest()
    return digest.hexdigest()


def _axis_name(path: Path, namespace: str, joint: str | None, several: bool,
               axis_from: str) -> str:
    own = joint if joint is not None else namespace
    if axis_from == "parent":
        parent = path.resolve().parent.name or "/"
        return f"{parent}:{own}" if several else parent
    return own


def units_of(path: Path, namespace: str | None = None, axis_from: str = "topic") -> list[Unit]:
    """The units of work of one recording: one per axis it holds (or the one ``namespace``
    names: a topic namespace or a JointState topic)."""
    from ..bagio import list_axes

    content = content_key(path)
    try:
        axes = list_axes(path)
    except PmsmSysidError:
        return [Unit(str(path), namespace, None, None, content)]  # its row says why
    if namespace is not None:
        axes = [a for a in axes if a[0] == namespace] or [(namespace, None)]
    if not axes:
        return [Unit(str(path), None, None, None, content)]
    several = len(axes) > 1
    return [Unit(str(path), ns, joint, _axis_name(path, ns, joint, several, axis_from),
                 content) for ns, joint in axes]


def all_units(paths: Iterable[Path], namespace: str | None = None,
              axis_from: str = "topic") -> Iterator[Unit]:
    """The units of every recording, in order."""
    for p in paths:
        yield from units_of(p, namespace, axis_from)
