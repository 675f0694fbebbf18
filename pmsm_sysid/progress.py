"""Progress on a terminal for long offline work (simulate, identify, diagnose, report), drawn
by rich (``rich.progress``).

Bars go to stderr and only when stderr is a terminal, so pipes, log files, CI and tests stay
quiet; ``--quiet`` on a verb (:func:`silence`) or ``PMSM_SYSID_PROGRESS=0`` silences them on
a terminal, ``PMSM_SYSID_PROGRESS=1`` forces them on (e.g. to see them through ``tee``).

    from pmsm_sysid.progress import activity, progress
    for chunk in progress(chunks, total=len(chunks), label="reading bag"):
        ...
    with activity("identify") as say:   # one long call: a pulsing bar and the elapsed time
        fit = identify(bag)
        say("writing")
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TextIO, TypeVar

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

T = TypeVar("T")
ENV = "PMSM_SYSID_PROGRESS"
_quiet = False


def silence(quiet: bool = True) -> bool:
    """No bars from now on in this process (the verbs' ``--quiet``); returns the previous
    setting, to restore it."""
    global _quiet
    previous, _quiet = _quiet, quiet
    return previous


def enabled(stream: TextIO | None = None) -> bool:
    """Whether bars are drawn on ``stream`` (default stderr): a TTY, unless overridden."""
    flag = os.environ.get(ENV, "").strip().lower()
    if flag in ("0", "no", "off", "false") or _quiet:
        return False
    if flag in ("1", "yes", "on", "true"):
        return True
    s = sys.stderr if stream is None else stream
    try:
        return bool(s.isatty())
    except (AttributeError, ValueError):  # closed or not a file
        return False


class RateColumn(ProgressColumn):
    """Items done per minute (rich's estimate over the last 30 s)."""

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        return Text("" if speed is None else f"{60 * speed:.3g}/min")


def _progress(stream: TextIO, counted: bool, auto: bool, counts: Sequence[str] = (),
              rate: bool = False) -> Progress:
    columns: list[ProgressColumn | str] = [TextColumn("{task.description}"), BarColumn()]
    if counted:
        columns += [TaskProgressColumn(), MofNCompleteColumn()]
        columns += [TextColumn(f"{name} {{task.fields[{name}]}}") for name in counts]
        columns += [RateColumn()] if rate else []
        columns += [TimeElapsedColumn(), TimeRemainingColumn()]
    else:
        columns += [TimeElapsedColumn()]
    console = Console(file=stream, force_terminal=True, highlight=False, emoji=False)
    return Progress(*columns, console=console, auto_refresh=auto, transient=False,
                    refresh_per_second=4)


class Bar:
    """A counted bar: ``update(n)`` adds n done; ``close()`` ends the line. ``counts``:
    names of further counters shown as ``name N`` (set with ``update(name=N)``); ``rate``:
    show the items done per minute."""

    def __init__(self, total: int | None, label: str = "", stream: TextIO | None = None,
                 min_interval: float = 0.1, force: bool | None = None,
                 counts: Sequence[str] = (), rate: bool = False) -> None:
        self.total = total
        self.label = label
        out = sys.stderr if stream is None else stream
        self.on = enabled(out) if force is None else force
        self.min_interval = min_interval
        self.done = 0
        self._last = -1.0
        self._closed = False
        self._bar: Progress | None = None
        if self.on:
            self._bar = _progress(out, counted=True, auto=False, counts=counts, rate=rate)
            zeros: dict[str, Any] = dict.fromkeys(counts, 0)
            self._task = self._bar.add_task(label, total=total, **zeros)
            self._bar.start()

    def update(self, n: int = 1, **counts: Any) -> None:
        self.done += n
        if self._bar is None:
            return
        self._bar.update(self._task, completed=self.done, **counts)
        now = time.monotonic()
        if now - self._last >= self.min_interval or self.done == self.total:
            self._last = now
            self._bar.refresh()

    def finish(self) -> None:
        """All the work is done (a count estimated up front may have been generous)."""
        if self.total is not None:
            self.done = max(self.done, self.total)
            if self._bar is not None:
                self._bar.update(self._task, total=self.done, completed=self.done)
        self.close()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._bar is not None:
            self._bar.refresh()
            self._bar.stop()

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


@contextmanager
def activity(label: str, stream: TextIO | None = None,
             force: bool | None = None) -> Iterator[Callable[[str], None]]:
    """A pulsing bar with the elapsed time while long calls run (only on a terminal);
    yields ``say(stage)`` to name the current stage."""
    out = sys.stderr if stream is None else stream
    if not (enabled(out) if force is None else force):
        yield lambda stage: None
        return
    bar = _progress(out, counted=False, auto=True)
    task = bar.add_task(label, total=None)

    def say(stage: str) -> None:
        bar.update(task, description=f"{label}: {stage}")

    bar.start()
    try:
        yield say
    finally:
        bar.update(task, total=1, completed=1)
        bar.stop()
