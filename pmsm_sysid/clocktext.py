"""A stamp in words: seconds on a simulated clock (which starts at 0), the UTC time of day
on the wall clock (whose stamps count from 1970 and mean nothing to a reader as seconds).
The live messages, the monitor and the run report all tell the two clocks apart here."""

from __future__ import annotations

from datetime import UTC, datetime

#: Stamps above this many seconds are wall-clock time (2001 on); a simulated clock starts at 0.
WALL_CLOCK_S = 1e9

__all__ = ["WALL_CLOCK_S", "is_wall_clock", "stamp_text", "time_of_day"]


def is_wall_clock(t: float) -> bool:
    """``t`` (s) is a wall-clock stamp, not a simulated clock's."""
    return t > WALL_CLOCK_S


def time_of_day(t: float, tenths: bool = True) -> str:
    """The UTC time of day of the wall-clock stamp ``t``: ``"13:54:30.0"`` (rounded to a
    tenth of a second) or, without ``tenths``, ``"13:54:30"`` (the whole seconds)."""
    if tenths:
        return datetime.fromtimestamp(round(t, 1), UTC).strftime("%H:%M:%S.%f")[:-5]
    return datetime.fromtimestamp(t, UTC).strftime("%H:%M:%S")


def stamp_text(t: float, digits: int = 1, prefix: str = "") -> str:
    """``t`` as ``prefix`` + seconds (``"t=30.0 s"`` with ``prefix="t="``) on a simulated
    clock, or as the UTC time of day to a tenth of a second (``"14:02:33.4 UTC"``).

    >>> stamp_text(30.0, prefix="t="), stamp_text(8.5, 2), stamp_text(1795787670.04)
    ('t=30.0 s', '8.50 s', '13:54:30.0 UTC')
    """
    if is_wall_clock(t):
        return f"{time_of_day(t)} UTC"
    return f"{prefix}{t:.{digits}f} s"
