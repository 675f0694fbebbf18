"""Option checks of the public API: one clear :class:`OptionError` before any work starts."""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Collection, Sequence
from typing import Any

from ..core.errors import OptionError


def count(name: str, value: Any, minimum: int = 0) -> int:
    """An integer >= ``minimum`` (bools are refused: ``True`` is no count)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise OptionError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise OptionError(f"{name} must be at least {minimum}, got {value}")
    return int(value)


def choice(name: str, value: Any, choices: Collection[Any]) -> Any:
    """One of ``choices``."""
    if value not in choices:
        valid = ", ".join(repr(c) for c in choices)
        raise OptionError(f"{name} must be one of {valid}, got {value!r}")
    return value


def _number(name: str, value: Any, ok: Callable[[float], bool], what: str) -> float:
    """``value`` as a float for which ``ok`` holds, else an :class:`OptionError` naming ``what``."""
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"{name} must be {what}, got {value!r}") from exc
    if not ok(x):
        raise OptionError(f"{name} must be {what}, got {value!r}")
    return x


def fraction(name: str, value: Any) -> float:
    """A number strictly between 0 and 1."""
    return _number(name, value, lambda x: 0 < x < 1, "a number in (0, 1)")


def positive(name: str, value: Any) -> float:
    """A finite number > 0."""
    return _number(name, value, lambda x: math.isfinite(x) and x > 0,
                   "a positive finite number")


def sample_range(name: str, value: Any) -> tuple[int, int]:
    """A ``(start, stop)`` pair of sample indices, 0-based half-open, 0 <= start < stop."""
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
        raise OptionError(f"{name} must be a (start, stop) pair of sample indices, "
                          f"got {value!r}")
    start, stop = value
    for v in (start, stop):
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            raise OptionError(f"{name} must hold integers, got {value!r}")
    if not 0 <= start < stop:
        raise OptionError(f"{name} needs 0 <= start < stop, got {value!r}")
    return int(start), int(stop)
