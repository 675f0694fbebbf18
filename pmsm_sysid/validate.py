"""The validation layer shared by the command line and the Python API (standard library only).

Everything a user hands over is checked here before any work starts: output paths (so a long
run never ends in "cannot write"), numbers (finite, in range), ROS names, JSON documents.
Each failure is one :class:`~pmsm_sysid.core.errors.PmsmSysidError` whose message names the
option (or key) and what is wrong; the CLI prints it as one line and exits with code 2.

Results are written atomically: to a temporary name beside the target, renamed into place
once complete, so an interrupted or failed write never leaves a file that looks valid.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from .core.errors import DataError, OptionError, OutputError

#: Largest number of samples a simulation or a run may produce (80 MB per float64 signal).
MAX_SAMPLES = 10_000_000
#: Largest seed accepted (numpy's generators take any integer >= 0; this keeps it printable).
MAX_SEED = 2**63 - 1
#: Largest thrust amplitude (N) an excitation may ask for.
MAX_AMPLITUDE_N = 1e6
#: Largest JSON input read (a model, a result): far above what any verb writes.
MAX_JSON_BYTES = 64 * 1024 * 1024

_NAME_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


# ----------------------------------------------------------------------------- output paths


def _describe(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _writable_dir(path: Path, option: str, target: Path) -> None:
    if not path.exists():
        raise OutputError(f"{option} {target}: directory {path} does not exist (create it first)")
    if not path.is_dir():
        raise OutputError(f"{option} {target}: {path} is not a directory")
    try:  # the only sure test (root passes os.access, read-only file systems do not)
        with tempfile.TemporaryFile(dir=path, prefix=".pmsm-sysid-probe."):
            pass
    except OSError as exc:
        raise OutputError(f"{option} {target}: cannot write in {path} ({_describe(exc)})") from exc


def check_output_file(path: str | Path | None, option: str, *, force: bool = False) -> Path | None:
    """Refuse an output file that cannot be written, or would overwrite one without ``force``.

    ``None`` and ``-`` (stdout) pass. Returns the path (None for stdout/absent).
    """
    if path is None or str(path) == "-":
        return None
    p = Path(path)
    if str(path) == "" or str(path).endswith(os.sep):
        raise OutputError(f"{option} '{path}': expected a file name")
    _writable_dir(p.parent if str(p.parent) else Path("."), option, p)
    if p.is_dir():
        raise OutputError(f"{option} {p}: is a directory, expected a file name")
    if p.exists() or p.is_symlink():
        if not force:
            raise OutputError(f"{option} {p}: exists already; use --force to replace it")
        if not p.is_file():
            raise OutputError(f"{option} {p}: exists and is not a regular file; not replacing it")
    return p


def check_output_dir(path: str | Path, option: str, *, force: bool = False,
                     is_ours: Callable[[Path], bool] | None = None, what: str = "directory",
                     ) -> Path:
    """Refuse an output directory (a bag, a report) that cannot be created or replaced.

    An existing path is replaced only with ``force`` and only when ``is_ours`` recognises it
    (a rosbag2 directory for a bag, a report for a report): a directory of other things is
    never deleted.
    """
    if str(path) == "":
        raise OutputError(f"{option}: expected a directory name")
    p = Path(path)
    _writable_dir(p.parent if str(p.parent) else Path("."), option, p)
    if p.exists() or p.is_symlink():
        if not force:
            raise OutputError(f"{option} {p}: exists already; use --force to replace it")
        if p.is_symlink() or not p.is_dir() or (is_ours is not None and not is_ours(p)):
            raise OutputError(f"{option} {p}: exists and is not a {what}; not replacing it")
    return p


def is_bag_dir(p: Path) -> bool:
    """A rosbag2 directory: it has a ``metadata.yaml``."""
    return (p / "metadata.yaml").is_file()


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str, option: str = "output") -> None:
    """Write ``text`` to a temporary file beside ``path`` and rename it into place."""
    p = Path(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
        os.fchmod(fd, 0o666 & ~_umask())  # as a plain open() would create it
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except OSError as exc:
        if tmp is not None:
            with suppress(OSError):
                os.unlink(tmp)
        raise OutputError(f"{option} {p}: cannot write ({_describe(exc)})") from exc
    except BaseException:
        if tmp is not None:
            with suppress(OSError):
                os.unlink(tmp)
        raise


@contextmanager
def atomic_dir(path: str | Path, option: str = "output") -> Iterator[Path]:
    """Yield a fresh path to build a directory at; on success it replaces ``path``.

    The directory is built under a hidden temporary directory beside ``path`` with the same
    final name (a rosbag2 storage file is named after its directory), then renamed into place;
    on any failure it is removed and ``path`` is left as it was.
    """
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    try:
        holder = Path(tempfile.mkdtemp(prefix=f".{p.name}.", suffix=".tmp", dir=parent))
    except OSError as exc:
        raise OutputError(f"{option} {p}: cannot write ({_describe(exc)})") from exc
    try:
        yield holder / p.name
        old = None
        if p.exists():
            old = holder / (p.name + ".old")
            os.replace(p, old)
        try:
            os.replace(holder / p.name, p)
        except OSError:
            if old is not None:
                os.replace(old, p)
            raise
    except OSError as exc:
        raise OutputError(f"{option} {p}: cannot write ({_describe(exc)})") from exc
    finally:
        shutil.rmtree(holder, ignore_errors=True)


def rescue_path(stem: str) -> Path:
    """Where a result that could not be written at its place is saved instead."""
    return Path(tempfile.gettempdir()) / f"{stem}-{os.getpid()}.json"


# ----------------------------------------------------------------------------- numbers


def _as_number(option: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise OptionError(f"{option} must be a number, got {value!r}")
    if isinstance(value, float) and math.isnan(value):
        raise OptionError(f"{option} must be a number, got nan")
    return float(value)


def check_number(option: str, value: Any, *, low: float | None = None,
                 high: float | None = None, low_open: bool = False,
                 unit: str = "") -> float:
    """A finite number in ``[low, high]`` (``(low, high]`` with ``low_open``)."""
    x = _as_number(option, value)
    if not math.isfinite(x):
        raise OptionError(f"{option} must be a finite number, got {value}")
    u = f" {unit}" if unit else ""
    if low is not None and (x < low or (low_open and x == low)):
        raise OptionError(f"{option} must be {'>' if low_open else '>='} {low:g}{u}, got {value}")
    if high is not None and x > high:
        raise OptionError(f"{option} must be at most {high:g}{u}, got {value}")
    return x


def check_int(option: str, value: Any, *, low: int | None = None,
              high: int | None = None) -> int:
    """An integer (not a boolean, not a float) in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise OptionError(f"{option} must be an integer, got {value!r}")
    if low is not None and value < low:
        raise OptionError(f"{option} must be >= {low}, got {value}")
    if high is not None and value > high:
        raise OptionError(f"{option} must be at most {high}, got {value}")
    return value


def check_seed(value: Any, option: str = "--seed") -> int:
    """A random-generator seed: an integer 0 .. 2**63-1."""
    return check_int(option, value, low=0, high=MAX_SEED)


def check_duration(value: Any, option: str = "--duration", *, rate_hz: float = 500.0) -> float:
    """Seconds of data: positive, finite, and at most :data:`MAX_SAMPLES` samples."""
    x = check_number(option, value, low=0.0, low_open=True, unit="s")
    if x * rate_hz > MAX_SAMPLES:
        raise OptionError(f"{option} {x:g} s at {rate_hz:g} Hz is {x * rate_hz:.3g} samples, "
                          f"more than the limit of {MAX_SAMPLES}; record in parts")
    return x


def check_range(option: str, value: tuple[int, int]) -> tuple[int, int]:
    """A half-open sample range ``START:STOP`` with 0 <= START < STOP."""
    start, stop = value
    if start < 0 or stop <= start:
        raise OptionError(f"{option} needs 0 <= START < STOP, got {start}:{stop}")
    return value


# ----------------------------------------------------------------------------- ROS names


def check_namespace(value: Any, option: str = "--namespace") -> str:
    """A ROS 2 namespace or topic name: ``/`` or tokens of letters, digits and ``_`` (not
    starting with a digit) separated by single ``/``; checked before rclpy sees it."""
    if not isinstance(value, str) or not value:
        raise OptionError(f"{option} must be a ROS name like /pmsm, got {value!r}")
    if value == "/":
        return value
    if len(value) > 200:
        raise OptionError(f"{option} is {len(value)} characters long; ROS names are at most 200")
    body = value[1:] if value.startswith("/") else value
    for token in body.split("/"):
        if not token:
            raise OptionError(f"{option} '{value}': empty name part (a '//' or a trailing '/'); "
                              "write e.g. /pmsm or /robot1/pmsm")
        if not _NAME_TOKEN.match(token):
            raise OptionError(f"{option} '{value}': '{token}' is not a ROS name part (letters, "
                              "digits and '_', not starting with a digit); write e.g. /pmsm")
    return value


# ----------------------------------------------------------------------------- JSON inputs


def read_json_object(path: str, what: str, *, stdin_text: str | None = None) -> dict[str, Any]:
    """Read a JSON document that must be an object (``path`` '-' = ``stdin_text``)."""
    name = "stdin" if path == "-" else path
    if path == "-":
        text = stdin_text or ""
    else:
        p = Path(path)
        try:
            if p.is_dir():
                raise DataError(f"{name}: is a directory, expected {what}")
            if p.stat().st_size > MAX_JSON_BYTES:
                raise DataError(f"{name}: {p.stat().st_size} bytes, too large for {what}")
            text = p.read_text(encoding="utf-8")
        except FileNotFoundError as exc:
            raise DataError(f"{name}: no such file") from exc
        except UnicodeDecodeError as exc:
            raise DataError(f"{name}: not a text file (expected {what})") from exc
        except OSError as exc:
            raise DataError(f"{name}: cannot read ({_describe(exc)})") from exc
    try:
        doc = json.loads(text)
    except RecursionError as exc:
        raise DataError(f"{name}: JSON nested too deeply (expected {what})") from exc
    except ValueError as exc:
        raise DataError(f"{name}: not valid JSON ({' '.join(str(exc).split())}); "
                        f"expected {what}") from exc
    if not isinstance(doc, dict):
        kind = {list: "a list", str: "a string", bool: "a boolean", type(None): "null"}.get(
            type(doc), "a number")
        raise DataError(f"{name}: the JSON is {kind}, expected {what} (an object)")
    return doc
