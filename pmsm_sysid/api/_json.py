"""Plain JSON values: what a verb's ``--json`` file holds, as Python data."""

from __future__ import annotations

import math
from typing import Any


def plain(obj: Any) -> Any:
    """Dicts, lists, str, int, float, bool and None only; numpy values become Python values,
    tuples become lists and non-finite floats become None (strict JSON has no NaN)."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if hasattr(obj, "tolist"):
        return plain(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
