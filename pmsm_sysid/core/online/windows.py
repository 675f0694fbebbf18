"""Windows of aligned samples: the second step of the identifier's data path (the first is
:class:`~.streaming.StampAligner`).

:class:`WindowScheduler` keeps a fixed-size ring of the latest aligned samples; every ``hop``
samples (on the absolute index grid, so two processes watching the same stamps cut the same
windows) it copies out the latest ``window`` contiguous samples as a :class:`Window`.
Memory is bounded: the ring has a fixed size.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..recording.signals import Recording
from .streaming import NS_PER_S, SIGNALS, Sample

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Window:
    """``n`` contiguous samples ending at absolute index ``stop_index - 1``.

    ``history`` extra samples before ``start_index`` are included at the front of the arrays
    (the lagged regressors of the first rows; ``data`` slices them off).
    """

    seq: int
    start_index: int
    stop_index: int
    history: int
    stamps_ns: NDArray[np.int64]
    values: FloatArray
    signals: tuple[str, ...] = SIGNALS
    due_monotonic: float = field(default=0.0, compare=False)
    speed_derived: bool = False  # speed was derived from position (no speed messages)

    @property
    def start_stamp(self) -> float:
        return float(self.stamps_ns[self.history]) / NS_PER_S

    @property
    def end_stamp(self) -> float:
        return float(self.stamps_ns[-1]) / NS_PER_S

    def signal(self, name: str, with_history: bool = False) -> FloatArray:
        col = self.values[:, self.signals.index(name)]
        return col if with_history else col[self.history:]

    def recording(self, sample_rate_hz: float, with_history: bool = True) -> Recording:
        """The window as a :class:`Recording` (history included unless asked otherwise)."""
        h = 0 if with_history else self.history
        t = self.stamps_ns[h:].astype(np.float64) / NS_PER_S
        cols = {s: np.ascontiguousarray(self.values[h:, i]) for i, s in enumerate(self.signals)}
        return Recording(t=t, thrust=cols["thrust"], speed=cols["speed"],
                         position=cols["position"], sample_rate_hz=sample_rate_hz,
                         speed_derived=self.speed_derived, source=f"window {self.seq}")


def _check_sizes(window: int, hop: int, history: int) -> None:
    if window < 2 or hop < 1 or history < 0:
        raise DataError(f"need window >= 2, hop >= 1, history >= 0 (got {window}, {hop}, "
                        f"{history})")


class WindowScheduler:
    """Ring of the latest samples; cuts a window whenever ``(index + 1) % hop == 0``.

    A window needs ``window + history`` contiguous samples (a gap restarts the count), so a
    window never spans missing data. ``capacity`` is exactly that: memory does not grow.
    """

    def __init__(self, window: int = 1000, hop: int = 250, history: int = 0,
                 n_signals: int = len(SIGNALS), signals: Sequence[str] = SIGNALS) -> None:
        _check_sizes(window, hop, history)
        self.window, self.hop, self.history = window, hop, history
        self.signals = tuple(signals)
        self.capacity = window + history
        self._stamps = np.zeros(self.capacity, dtype=np.int64)
        self._values = np.zeros((self.capacity, n_signals), dtype=np.float64)
        self._head = 0  # next write position
        self._run = 0  # contiguous samples ending at the newest one
        self._last_index: int | None = None
        self.samples = 0
        self.windows = 0

    def resize(self, window: int, hop: int, history: int) -> None:
        """New window, hop and history from the next sample on. The newest contiguous
        samples are kept (as many as the new ring holds), so the next window is cut as soon
        as the new ring is full of contiguous data and the hop grid says so."""
        _check_sizes(window, hop, history)
        capacity = window + history
        keep = min(self._run, self.capacity, capacity)
        order = np.r_[self._head:self.capacity, 0:self._head][self.capacity - keep:]
        stamps = np.zeros(capacity, dtype=np.int64)
        values = np.zeros((capacity, self._values.shape[1]), dtype=np.float64)
        stamps[:keep], values[:keep] = self._stamps[order], self._values[order]
        self._stamps, self._values = stamps, values
        self._head, self._run = keep % capacity, keep
        self.window, self.hop, self.history, self.capacity = window, hop, history, capacity

    def push(self, sample: Sample) -> Window | None:
        """Store ``sample``; return the window it completes, if any."""
        contiguous = self._last_index is not None and sample.index == self._last_index + 1
        self._run = self._run + 1 if contiguous else 1
        self._last_index = sample.index
        self._stamps[self._head] = sample.stamp_ns
        self._values[self._head] = sample.values
        self._head = (self._head + 1) % self.capacity
        self.samples += 1
        if (sample.index + 1) % self.hop or self._run < self.capacity:
            return None
        order = np.r_[self._head:self.capacity, 0:self._head]
        self.windows += 1
        stop = sample.index + 1
        return Window(seq=stop // self.hop, start_index=stop - self.window, stop_index=stop,
                      history=self.history, stamps_ns=self._stamps[order],
                      values=self._values[order], signals=self.signals,
                      due_monotonic=time.monotonic())
