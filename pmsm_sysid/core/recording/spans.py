"""Which part of a long recording is used: spans spread evenly over it, within a budget.

The fitting and diagnosis stages hold every sample they use several times over (smoothed
states, filtered candidate columns, replays), so a recording longer than ``max_samples``
is not used whole: ``SPANS`` equal spans of ``max_samples / SPANS`` samples are taken,
spread evenly over it -- the first starts at its first sample and the last ends at its
last, so a drift, a slow disturbance or a change between the start and the end are still
in the data. When part of the recording is held out (its last 30 %), the spans are
planned in each part separately, in proportion to the budget: seven spans in the
estimation part and three in the held-out part. The choice depends on the length only,
never on the data, so the statistics of every test keep their meaning: the spans are a
recording of that many samples, with gaps.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DataError
from .signals import Recording

#: Samples used at most (over all spans); about 2 minutes at 1 kHz.
MAX_SAMPLES = 120_000
#: Spans a recording over the budget is cut into (held-out part included).
SPANS = 10
#: The shortest span worth its edges (filter start-up, replay horizons, a NARX window).
MIN_SPAN = 2_000


Parts = Recording | Sequence[Recording]
"""A recording, or the contiguous parts of one used in its place (spans of a long one)."""


def as_parts(rec: Parts) -> list[Recording]:
    """``rec`` as a list of contiguous recordings."""
    return [rec] if isinstance(rec, Recording) else list(rec)


def check_budget(max_samples: int) -> int:
    """``max_samples`` as an int, or a DataError naming the smallest budget allowed."""
    n = int(max_samples)
    if n != max_samples or n < SPANS * MIN_SPAN:
        raise DataError(f"max_samples must be a whole number of at least {SPANS * MIN_SPAN} "
                        f"({SPANS} spans of {MIN_SPAN} samples), got {max_samples}")
    return n


def _spread(start: int, stop: int, count: int, length: int) -> list[tuple[int, int]]:
    """``count`` spans of ``length`` samples from ``start`` to ``stop``, evenly spaced
    (fewer if they would overlap)."""
    length = min(length, stop - start)
    count = max(1, min(count, (stop - start) // length))
    if count == 1:
        mid = start + (stop - start - length) // 2
        return [(mid, mid + length)]
    room = stop - start - length
    firsts = [start + round(i * room / (count - 1)) for i in range(count)]
    return [(a, a + length) for a in firsts]


def plan_spans(total: int, max_samples: int = MAX_SAMPLES,
               split: float | None = None) -> tuple[tuple[int, int], ...]:
    """Sample ranges (start, stop) to use of a recording of ``total`` samples.

    All of it when it fits ``max_samples``; else ``SPANS`` spans of ``max_samples //
    SPANS`` samples spread evenly over it. ``split`` (the estimation share of a recording
    whose end is held out): the spans are planned in ``[0, cut)`` and ``[cut, total)``
    apart, in proportion, so none straddles the cut.
    """
    budget = check_budget(max_samples)
    if total <= budget:
        return ((0, total),)
    length = budget // SPANS
    if split is None:
        return tuple(_spread(0, total, SPANS, length))
    cut = int(split * total)
    first = min(SPANS - 1, max(1, round(split * SPANS)))
    return tuple(_spread(0, cut, first, length) + _spread(cut, total, SPANS - first, length))


@dataclass(frozen=True)
class Excerpt:
    """The spans of a recording that are used, one contiguous recording each.

    ``parts`` are views into ``joined`` (the parts end to end; its stamps jump between
    parts), ``starts`` the index of each part's first sample in the whole recording of
    ``total`` samples.
    """

    joined: Recording
    lengths: tuple[int, ...]
    starts: tuple[int, ...]
    total: int

    @property
    def parts(self) -> tuple[Recording, ...]:
        edges = np.cumsum((0, *self.lengths))
        return tuple(self.joined.window(int(a), int(b)) for a, b in itertools.pairwise(edges))

    @property
    def whole(self) -> bool:
        """Every sample of the recording is used."""
        return sum(self.lengths) == self.total

    @property
    def used(self) -> int:
        return sum(self.lengths)

    def ranges(self) -> tuple[tuple[int, int], ...]:
        """(start, stop) of each part in the whole recording."""
        return tuple((s, s + n) for s, n in zip(self.starts, self.lengths, strict=True))

    def describe(self, held_out: int = 0) -> dict[str, Any]:
        """What was used, for the JSON's ``method`` (``held_out``: how many of the last
        spans are held-out data)."""
        fs = self.joined.sample_rate_hz
        return {"samples": self.used, "of_samples": self.total, "seconds": self.used / fs,
                "of_seconds": self.total / fs, "whole": self.whole,
                "spans": [list(r) for r in self.ranges()],
                "span_times_s": [[float(p.t[0]), float(p.t[-1])] for p in self.parts],
                "text": self.text(held_out)}

    def text(self, held_out: int = 0) -> str:
        """One sentence saying what part of the recording was used, and why."""
        fs = self.joined.sample_rate_hz
        if self.whole:
            return f"all {self.total} samples ({self.total / fs:.4g} s)"
        spans = ", ".join(f"{a}-{b}" for a, b in self.ranges())
        n = len(self.lengths)
        where = (f"; the last {held_out} held out" if 0 < held_out < n else "")
        return (f"{self.used / fs:.4g} s of {self.total / fs:.4g} s ({self.used} of "
                f"{self.total} samples) in {n} spans of {self.lengths[0] / fs:.3g} s spread "
                f"evenly from its start to its end, so that slow changes are seen "
                f"(samples {spans}{where}); a longer recording costs no more memory or time")


def excerpt_of(rec: Recording, ranges: tuple[tuple[int, int], ...] | None = None,
               total: int | None = None) -> Excerpt:
    """The ``ranges`` of ``rec`` (default: all of it) as an :class:`Excerpt` of a recording
    of ``total`` samples (default ``len(rec)``: the ranges index ``rec``)."""
    ranges = ranges or ((0, len(rec)),)
    whole = ranges == ((0, len(rec)),)
    joined = rec if whole else concat([rec.window(a, b) for a, b in ranges])
    return Excerpt(joined, tuple(b - a for a, b in ranges), tuple(a for a, _ in ranges),
                   len(rec) if total is None else total)


def concat(parts: Sequence[Recording]) -> Recording:
    """Recordings end to end as one (stamps jump between them); a single one as it is."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    cat = {name: np.concatenate([getattr(p, name) for p in parts])
           for name in ("t", "thrust", "speed", "position")}
    return Recording(**cat, sample_rate_hz=first.sample_rate_hz,
                     speed_derived=first.speed_derived, source=first.source, meta=first.meta)


def join(parts: list[tuple[Recording, int]], total: int) -> Excerpt:
    """Parts read apart (each with the index of its first sample) as one :class:`Excerpt`."""
    if not parts:
        raise DataError("no samples in the spans read")
    return Excerpt(concat([p for p, _ in parts]), tuple(len(p) for p, _ in parts),
                   tuple(s for _, s in parts), total)


__all__ = ["MAX_SAMPLES", "MIN_SPAN", "SPANS", "Excerpt", "Parts", "as_parts", "check_budget",
           "concat", "excerpt_of", "join", "plan_spans"]
