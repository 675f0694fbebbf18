"""Spans in seconds on a stream whose sample rate is read from the stamps (no ROS).

The live diagnosis works in seconds (a ``span_s`` diagnosed every ``period_s``) on the same
window ring the identifier uses (:class:`~.windows.WindowScheduler`, cut on the absolute
sample grid), which counts in samples. :func:`samples_of` converts once the aligner knows
the sample period; until then a provisional rate sizes the ring (the aligner emits no sample
before it knows the period, so nothing is cut at the provisional size).

:class:`LatestSpan` keeps the latest span of a second source (a simulator running beside the
drive): its own :class:`~.inputs.InputAligner` and window ring, and the newest span cut.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

from ..errors import DataError
from .inputs import InputAligner
from .streaming import NS_PER_S, SIGNALS, Sample
from .windows import Window, WindowScheduler


def samples_of(seconds: float, period_ns: int) -> int:
    """Whole samples in ``seconds`` at a sample period of ``period_ns`` (at least 2)."""
    if not (math.isfinite(seconds) and seconds > 0) or period_ns <= 0:
        raise DataError(f"need a positive duration and sample period (got {seconds} s, "
                        f"{period_ns} ns)")
    return max(2, round(seconds * NS_PER_S / period_ns))


class SpanSizer:
    """Keeps a window ring sized ``span_s``/``period_s`` in samples of the stream's rate.

    ``resize(window, hop)`` is called whenever the sizes in samples change: when the
    aligner's period becomes known (or differs from the provisional rate) and when the
    seconds change (:meth:`set_seconds`)."""

    def __init__(self, span_s: float, period_s: float, provisional_hz: float,
                 resize: Callable[[int, int], None]) -> None:
        self._resize = resize
        self._period_ns = round(NS_PER_S / provisional_hz)
        self.span_s, self.period_s = float(span_s), float(period_s)
        self.sizes = self._sizes()

    def _sizes(self) -> tuple[int, int]:
        return samples_of(self.span_s, self._period_ns), samples_of(self.period_s,
                                                                    self._period_ns)

    def _apply(self) -> None:
        sizes = self._sizes()
        if sizes != self.sizes:
            self.sizes = sizes
            self._resize(*sizes)

    def check(self, period_ns: int | None) -> None:
        """The aligner's period now (None while unknown): resize if it changed the sizes."""
        if period_ns and period_ns != self._period_ns:
            self._period_ns = period_ns
            self._apply()

    def set_seconds(self, span_s: float, period_s: float) -> None:
        self.span_s, self.period_s = float(span_s), float(period_s)
        self._apply()


class LatestSpan:
    """Aligned samples of one source and the latest span cut from them every period.

    ``latest`` is the newest :class:`Window` of ``span`` contiguous samples, cut whenever the
    absolute sample index reaches a multiple of ``period`` (None before the first);
    ``dropped`` counts samples with a non-finite value (not stored, nothing invented)."""

    def __init__(self, span: int, period: int, speed_source: str = "auto",
                 speed_expected: Callable[[], bool] | None = None,
                 tolerance_ns: int | None = None, period_ns: int | None = None) -> None:
        self.aligner = InputAligner(SIGNALS, speed_source, tolerance_ns=tolerance_ns,
                                    period_ns=period_ns, speed_expected=speed_expected)
        self.scheduler = WindowScheduler(span, period, 0, len(SIGNALS), SIGNALS)
        self.latest: Window | None = None
        self.dropped = 0

    def push(self, signal: str, stamp_ns: int, value: float) -> None:
        """One message of one signal."""
        self._store(self.aligner.push(signal, stamp_ns, value))

    def resize(self, span: int, period: int) -> None:
        self.scheduler.resize(span, period, 0)

    def _store(self, samples: list[Sample]) -> None:
        for s in samples:
            if not all(math.isfinite(v) for v in s.values):
                self.dropped += 1
                continue
            window = self.scheduler.push(s)
            if window is not None:
                self.latest = replace(window, speed_derived=self.aligner.speed_derived)

    @property
    def sample_rate_hz(self) -> float | None:
        """The source's sample rate read from its stamps (None while unknown)."""
        period = self.aligner.period_ns
        return NS_PER_S / period if period else None
