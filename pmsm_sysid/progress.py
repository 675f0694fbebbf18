"""Progress bars for long offline work (large bags, grid evaluation, report figures).

A bar is drawn on stderr only when stderr is a terminal, so pipes, log files, CI and tests
stay quiet. ``PMSM_SYSID_PROGRESS=0`` silences bars on a terminal; ``=1`` forces them on
(e.g. to see them through ``tee``). Standard library only; redraws at most every
``min_interval`` seconds, so wrapping a tight loop costs little.

    from pmsm_sysid.progress import progress
    for chunk in progress(chunks, total=len(chunks), label="reading bag"):
        ...
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable, Iterator
from typing import TextIO, TypeVar

T = TypeVar("T")
ENV = "PMSM_SYSID_PROGRESS"
WIDTH = 28


def enabled(stream: TextIO | None = None) -> bool:
    """Whether bars are drawn on ``stream`` (default stderr): a TTY, unless overridden."""
    flag = os.environ.get(ENV, "").strip().lower()
    if flag in ("0", "no", "off", "false"):
        return False
    if flag in ("1", "yes", "on", "true"):
        return True
    s = sys.stderr if stream is None else stream
    try:
        return bool(s.isatty())
    except (AttributeError, ValueError):  # closed or not a file
        return False


def _clock(seconds: float) -> str:
    m, s = divmod(int(seconds), 60)
    return f"{m}:{s:02d}"


def render(done: int, total: int | None, label: str, elapsed: float) -> str:
    """One bar line (without the leading carriage return)."""
    head = f"{label} " if label else ""
    if total is None or total <= 0:
        return f"{head}{done} {_clock(elapsed)}"
    frac = min(max(done / total, 0.0), 1.0)
    fill = round(frac * WIDTH)
    eta = ""
    if 0 < done < total:
        eta = f" eta {_clock(elapsed * (total - done) / done)}"
    return (f"{head}[{'#' * fill}{'.' * (WIDTH - fill)}] {100 * frac:3.0f}% "
            f"{done}/{total} {_clock(elapsed)}{eta}")


class Bar:
    """A manual bar: ``update(n)`` adds n done; ``close()`` ends the line."""

    def __init__(self, total: int | None, label: str = "", stream: TextIO | None = None,
                 min_interval: float = 0.1, force: bool | None = None) -> None:
        self.total = total
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.on = enabled(self.stream) if force is None else force
        self.min_interval = min_interval
        self.done = 0
        self._t0 = time.monotonic()
        self._last = -1.0
        self._width = 0
        self._closed = False

    def update(self, n: int = 1) -> None:
        self.done += n
        now = time.monotonic()
        if self.on and (now - self._last >= self.min_interval or self.done == self.total):
            self._draw(now)

    def _draw(self, now: float) -> None:
        self._last = now
        line = render(self.done, self.total, self.label, now - self._t0)
        pad = " " * max(0, self._width - len(line))
        self._width = len(line)
        try:
            self.stream.write("\r" + line + pad)
            self.stream.flush()
        except (OSError, ValueError):
            self.on = False

    def finish(self) -> None:
        """All the work is done (a count estimated up front may have been generous)."""
        if self.total is not None:
            self.done = max(self.done, self.total)
        self.close()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self.on:
            self._draw(time.monotonic())
            try:
                self.stream.write("\n")
                self.stream.flush()
            except (OSError, ValueError):
                pass

    def __enter__(self) -> Bar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress(iterable: Iterable[T], total: int | None = None, label: str = "",
             stream: TextIO | None = None, force: bool | None = None) -> Iterator[T]:
    """Yield the items of ``iterable`` while drawing a bar (only on a terminal).

    ``total`` defaults to ``len(iterable)`` when it has one; without a total the bar shows
    a count. ``force`` True/False overrides the terminal check (tests, explicit flags).
    """
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    with Bar(total, label, stream=stream, force=force) as bar:
        for item in iterable:
            yield item
            bar.update()
