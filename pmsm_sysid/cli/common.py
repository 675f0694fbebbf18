"""Small helpers shared by the verb modules (stdlib only at import time)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

from ..validate import MAX_AMPLITUDE_N as MAX_AMPLITUDE_N  # for the verbs


def _clean(obj: Any) -> Any:
    """Make numpy scalars/arrays and non-finite floats JSON-safe (NaN/Inf -> null)."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _clean(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(obj: Any, dest: str | None, option: str = "--json") -> None:
    """Write ``obj`` as JSON to ``dest`` (a path, or ``-`` for stdout); no-op for None.

    A file is written under a temporary name and renamed into place, so it is either complete
    or absent. If it cannot be written now (checked at the start, so only when the place
    changed meanwhile), the result is saved in the temporary directory instead and the error
    names where: a long run never loses its result.
    """
    if dest is None:
        return
    text = json.dumps(_clean(obj), indent=2, allow_nan=False) + "\n"
    if dest == "-":
        sys.stdout.write(text)
        return
    from ..core.errors import OutputError
    from ..validate import atomic_write_text, rescue_path

    try:
        atomic_write_text(dest, text, option)
    except OutputError as exc:
        spare = rescue_path("pmsm-sysid-" + Path(dest).stem)
        try:
            atomic_write_text(spare, text, option)
        except OutputError:
            raise exc from None
        raise OutputError(f"{exc}; the result was saved to {spare} instead") from exc


def write_text(text: str, dest: str | Path, option: str) -> None:
    """Write a text result (e.g. a plant file) atomically, as :func:`write_json`."""
    from ..validate import atomic_write_text

    atomic_write_text(dest, text, option)


#: What each kind of output option holds, for :func:`check_outputs`.
OUTPUT_KINDS = ("file", "bag", "report")


def check_outputs(args: Any, outputs: dict[str, str]) -> None:
    """Check every output path of a verb before any work starts (one shared rule).

    ``outputs`` maps an argument name (``json``, ``out``, ``record``, ``report``...) to what it
    holds: ``file``, ``bag`` (a rosbag2 directory) or ``report`` (a directory with an
    ``index.html``). Missing parent directory, a directory where a file is expected, an
    existing result without ``--force``, a place that cannot be written: one OutputError.
    """
    from ..core.errors import OutputError
    from ..validate import check_output_dir, check_output_file, is_bag_dir

    force = bool(getattr(args, "force", False))
    seen: dict[Path, str] = {}
    for attr, kind in outputs.items():
        value = getattr(args, attr, None)
        if value is None or value == "-":
            continue
        option = "--" + attr.replace("_", "-")
        if kind == "file":
            check_output_file(value, option, force=force)
        elif kind == "bag":
            check_output_dir(value, option, force=force, is_ours=is_bag_dir,
                             what="rosbag2 directory")
        else:
            check_output_dir(value, option, force=force,
                             is_ours=lambda p: (p / "index.html").is_file(), what="report")
        key = Path(value).resolve()
        if key in seen:
            raise OutputError(f"{option} and {seen[key]} name the same path {value}")
        seen[key] = option


def read_json(path: str) -> Any:
    """Read a JSON result file (an object), raising the project's DataError on any problem."""
    from ..validate import read_json_object

    return read_json_object(path, "a result JSON of pmsm-sysid")


def parse_range(text: str) -> tuple[int, int]:
    """Parse ``START:STOP`` (0-based half-open) for argparse."""
    import argparse

    try:
        a, b = text.split(":")
        start, stop = int(a), int(b)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected START:STOP, got '{text}'") from exc
    if start < 0 or stop <= start:
        raise argparse.ArgumentTypeError(f"need 0 <= START < STOP, got '{text}'")
    return start, stop


def budget(text: str) -> int:
    """--max-samples: a whole number, at least ten spans of the shortest span."""
    import argparse

    from ..core.recording.spans import MIN_SPAN, SPANS

    low = SPANS * MIN_SPAN
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < low:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least {low} "
                                         f"(ten spans of {MIN_SPAN} samples), got '{text}'")
    return value


def parse_fraction(text: str) -> float:
    """A number strictly between 0 and 1 (for argparse)."""
    import argparse

    try:
        value = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from exc
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1), got '{text}'")
    return value


#: Longest --duration of a live verb (run, record, monitor): 11.6 days; without --duration
#: they run until Ctrl-C or SIGTERM.
MAX_LIVE_S = 1e6


def _argtype(check: Any, name: str) -> Any:
    """An argparse type: parse a number, then ``check`` it; any problem is a usage error."""
    import argparse

    from ..core.errors import OptionError

    def parse(text: str) -> Any:
        try:
            value: Any = int(text)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
        try:
            return check(value)
        except OptionError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("value ")) from exc

    parse.__name__ = name
    return parse


def number(low: float | None = None, high: float | None = None, *,
           low_open: bool = False, unit: str = "") -> Any:
    """argparse type: a finite number in [low, high] ((low, high] with ``low_open``)."""
    from ..validate import check_number

    return _argtype(lambda v: check_number("value", v, low=low, high=high, low_open=low_open,
                                           unit=unit), "number")


def count(low: int = 0, high: int | None = None) -> Any:
    """argparse type: an integer in [low, high]."""
    from ..validate import check_int

    return _argtype(lambda v: check_int("value", v, low=low, high=high), "integer")


def seed_type(text: str) -> int:
    """argparse type of ``--seed``: an integer 0 .. 2**63-1."""
    from ..validate import MAX_SEED

    result: int = count(0, MAX_SEED)(text)
    return result


def live_seconds(text: str) -> float:
    """argparse type of a live verb's ``--duration``: finite, > 0, at most :data:`MAX_LIVE_S`."""
    result: float = number(0, MAX_LIVE_S, low_open=True, unit="s")(text)
    return result


def wait_seconds(text: str) -> float:
    """argparse type of ``--wait``: finite, >= 0, at most :data:`MAX_LIVE_S`."""
    result: float = number(0, MAX_LIVE_S, unit="s")(text)
    return result


def ros_name(text: str) -> str:
    """argparse type of ``--namespace`` and topic names: a valid ROS 2 name, checked before
    rclpy (or a bag's topic list) sees it."""
    import argparse

    from ..core.errors import OptionError
    from ..validate import check_namespace

    try:
        return check_namespace(text, "name")
    except OptionError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("name ")) from exc


def replace_bag_dir(out: Path, force: bool) -> None:
    """Make room for a new bag at ``out``: refuse unless ``force``, and never delete a
    directory that is not a rosbag2 bag."""
    from ..validate import check_output_dir, is_bag_dir

    if not out.exists():
        return
    check_output_dir(out, "--out", force=force, is_ours=is_bag_dir, what="rosbag2 directory")
    import shutil

    shutil.rmtree(out)
