"""Small helpers shared by the verb modules (stdlib only at import time)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any


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


def write_json(obj: Any, dest: str | None) -> None:
    """Write ``obj`` as JSON to ``dest`` (a path, or ``-`` for stdout); no-op for None."""
    if dest is None:
        return
    text = json.dumps(_clean(obj), indent=2, allow_nan=False)
    if dest == "-":
        sys.stdout.write(text + "\n")
    else:
        path = Path(dest)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text + "\n")


def read_json(path: str) -> Any:
    """Read a JSON result file, raising the project's DataError on any problem."""
    from ..core.errors import DataError

    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError as exc:
        raise DataError(f"{path}: no such file") from exc
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: not readable JSON ({exc})") from exc


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


def replace_bag_dir(out: Path, force: bool) -> None:
    """Make room for a new bag at ``out``: refuse unless ``force``, and never delete a
    directory that is not a rosbag2 bag."""
    from ..core.errors import BagError

    if not out.exists():
        return
    if not force:
        raise BagError(f"{out} exists already; use --force to replace it")
    if not out.is_dir() or not (out / "metadata.yaml").is_file():
        raise BagError(f"{out} exists and is not a rosbag2 directory; not replacing it")
    import shutil

    shutil.rmtree(out)
