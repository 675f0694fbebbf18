"""The fleet table on disk: ``DIR/results.parquet`` (Apache Parquet, written with pyarrow),
kept readable and complete at every moment.

Each finished row is first written as its own small Parquet file under ``DIR/parts/`` (to a
temporary name, then renamed), so a batch killed at any point keeps every row it finished;
``results.parquet`` is rewritten from all rows every few seconds and at the end, again under
a temporary name renamed into place, so a reader never sees a half-written table. A resumed
batch reads both back and skips the recordings already analysed. ``DIR/fleet.json`` records
the reference plant and the options the rows were made with; a batch resumed with others
is refused rather than mixing two kinds of rows in one table.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Mapping
from contextlib import suppress
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from ..core.errors import OutputError
from ..core.fleet import columns, empty_row

RESULTS = "results.parquet"
PARTS = "parts"
MANIFEST = "fleet.json"
ALARMS = "alarms.json"
PAGE = "index.html"
FIGURE_PREFIX = "trend_"
#: What a fleet output directory may hold besides hidden temporary files.
OURS = (RESULTS, PARTS, MANIFEST, ALARMS, PAGE)

_HARMONIC = pa.struct([("order", pa.int64()), ("amplitude_n", pa.float64()),
                       ("phase_rad", pa.float64())])
#: Times are stored to the microsecond (what Python's datetime holds), in UTC.
_TIME = pa.timestamp("us", tz="UTC")
_PER_S = 1_000_000
_TYPES: dict[str, pa.DataType] = {
    "recording": pa.string(), "axis": pa.string(), "start_time": _TIME,
    "status": pa.string(), "error": pa.string(), "effects": pa.list_(pa.string()),
    "diagnosed": pa.list_(pa.string()), "samples": pa.int64(), "speed_derived": pa.bool_(),
    "namespace": pa.string(), "joint": pa.string(), "content_sha256": pa.string(),
    "analysed_at": _TIME,
}


def _type(name: str) -> pa.DataType:
    if name in _TYPES:
        return _TYPES[name]
    if name.endswith((".harmonics", ".harmonics.std")):
        return pa.list_(_HARMONIC)
    if name.endswith(".confidence"):
        return pa.string()
    return pa.float64()


def schema() -> pa.Schema:
    """The table's schema: every column of :func:`pmsm_sysid.core.fleet.columns`."""
    return pa.schema([pa.field(c, _type(c)) for c in columns()])


def _ticks(seconds: Any) -> int | None:
    return None if seconds is None else round(float(seconds) * _PER_S)


def to_table(rows: Iterable[Mapping[str, Any]]) -> pa.Table:
    """Rows (start_time, analysed_at in s since 1970) as a table of the fleet schema."""
    rows = list(rows)
    data = {}
    for field in schema():
        values = [r.get(field.name) for r in rows]
        if field.type == _TIME:
            values = [_ticks(v) for v in values]
        data[field.name] = pa.array(values, type=field.type)
    return pa.table(data, schema=schema())


def from_table(table: pa.Table) -> list[dict[str, Any]]:
    """The rows of a fleet table as dicts (times as s since 1970 UTC); columns the table
    lacks (written by an older version) are empty."""
    out = []
    names = set(table.column_names)
    times = {c: table.column(c).cast(pa.int64()).to_pylist()
             for c in ("start_time", "analysed_at") if c in names}
    plain = table.drop_columns(list(times)).to_pylist()
    for i, row in enumerate(plain):
        r = empty_row() | row
        for c, v in times.items():
            r[c] = None if v[i] is None else v[i] / _PER_S
        out.append(r)
    return out


def row_key(row: Mapping[str, Any]) -> str:
    """The row's identity: its recording's content and the axis read from it."""
    return f"{row.get('content_sha256')}:{row.get('namespace') or ''}:{row.get('joint') or ''}"


def write_table(table: pa.Table, path: Path) -> None:
    """Write a Parquet file under a temporary name beside ``path``, then rename it in."""
    from ..validate import _umask

    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # as a plain open() would create it
        with os.fdopen(fd, "wb") as fh:
            pq.write_table(table, fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with suppress(OSError):
            os.unlink(tmp)
        raise


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of one fleet Parquet file."""
    try:
        return from_table(pq.read_table(path))
    except (OSError, pa.ArrowException) as exc:
        raise OutputError(f"{path}: cannot be read as a fleet table ({exc})") from exc


def _entries(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if not p.name.startswith("."))


def _ours(name: str) -> bool:
    return name in OURS or (name.startswith(FIGURE_PREFIX) and name.endswith(".png"))


def check_out_dir(out: Path, *, resume: bool, force: bool) -> bool:
    """Refuse an output directory before any work; True when it holds a fleet result to
    resume. A new or empty directory is fine; one holding a fleet result needs ``resume``
    (add to it) or ``force`` (start again); one holding anything else is never used."""
    from ..validate import check_output_dir, check_output_file

    if not out.exists() and not out.is_symlink():
        check_output_dir(out, "--out")  # the parent exists and can be written
        return False
    if out.is_symlink() or not out.is_dir():
        raise OutputError(f"--out {out}: exists and is not a directory")
    try:
        names = _entries(out)
    except OSError as exc:
        raise OutputError(f"--out {out}: cannot list ({exc.strerror or exc})") from exc
    others = [n for n in names if not _ours(n)]
    if others or (names and MANIFEST not in names):
        shown = ", ".join((others or names)[:3]) + (" ..." if len(others or names) > 3 else "")
        raise OutputError(f"--out {out}: holds other things ({shown}); give a new or empty "
                          "directory, or one a fleet batch wrote")
    check_output_file(out / MANIFEST, "--out", force=True)  # can be written
    if not names:
        return False
    if not (resume or force):
        raise OutputError(f"--out {out}: holds a fleet result already; --resume adds the "
                          "recordings not yet in it, --force starts again")
    return resume


def _digest(row: Mapping[str, Any]) -> str:
    return hashlib.sha256(row_key(row).encode()).hexdigest()[:40]


class Store:
    """The rows of one output directory: read back on resume, added one by one. With no
    directory (``out`` None) the rows are kept in memory only."""

    def __init__(self, out: Path | None) -> None:
        self.out = out
        self.parts = None if out is None else out / PARTS
        self.rows: dict[str, dict[str, Any]] = {}
        self.dirty = False

    def open(self, manifest: Mapping[str, Any], *, resume: bool) -> None:
        """Start a batch: a fresh directory (``resume`` False; our old files are removed),
        or the rows already there (``resume``: the manifest must match)."""
        if self.out is None or self.parts is None:
            return
        self.out.mkdir(exist_ok=True)
        for d in (self.out, self.parts):  # what a killed batch left half-written
            for tmp in d.glob(".*.tmp") if d.is_dir() else ():
                tmp.unlink(missing_ok=True)
        if resume:
            self._check_manifest(manifest)
            if (self.out / RESULTS).is_file():
                for r in read_rows(self.out / RESULTS):
                    self.rows[row_key(r)] = r
            for part in sorted(self.parts.glob("*.parquet")) if self.parts.is_dir() else ():
                for r in read_rows(part):
                    self.rows[row_key(r)] = r
        else:
            self._clear()
        from ..validate import atomic_write_text

        atomic_write_text(self.out / MANIFEST, json.dumps(manifest, indent=2) + "\n", "--out")
        self.parts.mkdir(exist_ok=True)
        if self.rows:
            self.flush()

    def _check_manifest(self, manifest: Mapping[str, Any]) -> None:
        assert self.out is not None
        try:
            old = json.loads((self.out / MANIFEST).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise OutputError(f"--out {self.out}: its {MANIFEST} cannot be read ({exc}); "
                              "--force starts again") from exc
        for key in ("reference", "options"):
            if old.get(key) != manifest.get(key):
                raise OutputError(
                    f"--out {self.out}: its rows were made with another {key} "
                    f"({_differs(old.get(key), manifest.get(key))}); use a new --out, or "
                    "--force to start again")

    def _clear(self) -> None:
        assert self.out is not None
        for name in _entries(self.out) if self.out.is_dir() else []:
            p = self.out / name
            if p.is_dir():
                shutil.rmtree(p)
            elif _ours(name):
                p.unlink()

    def done(self) -> set[str]:
        """Keys of the rows analysed without error (a resumed batch skips them)."""
        return {k for k, r in self.rows.items() if r.get("status") == "ok"}

    def add(self, row: Mapping[str, Any]) -> None:
        """Keep a finished row: on disk at once (its own part file), in the table at the
        next :meth:`flush`."""
        if self.parts is not None:
            write_table(to_table([row]), self.parts / f"{_digest(row)}.parquet")
        self.rows[row_key(row)] = dict(row)
        self.dirty = True

    def table(self) -> pa.Table:
        """Every row, by axis, start time and recording."""
        rows = sorted(self.rows.values(), key=lambda r: (
            r.get("axis") or "", r.get("start_time") or 0.0, r.get("recording") or ""))
        return to_table(rows)

    def flush(self) -> None:
        """Rewrite results.parquet from every row (atomically)."""
        if self.out is not None:
            write_table(self.table(), self.out / RESULTS)
        self.dirty = False

    def close(self) -> None:
        """Final table written; the part files it now holds are removed."""
        self.flush()
        if self.parts is not None:
            shutil.rmtree(self.parts, ignore_errors=True)


def _differs(old: Any, new: Any) -> str:
    if isinstance(old, Mapping) and isinstance(new, Mapping):
        keys = sorted(k for k in {*old, *new} if old.get(k) != new.get(k))
        return ", ".join(f"{k}: {old.get(k)!r} then, {new.get(k)!r} now" for k in keys[:3])
    return f"{old!r} then, {new!r} now"
