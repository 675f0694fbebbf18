"""The online identification engine: messages in, window results out (no ROS).

``push`` (the subscription path) aligns messages into samples (:class:`.inputs.InputAligner`:
the signals present, speed derived from position when it is not published), stores
them in the window ring (:class:`WindowScheduler`) and, every ``hop`` samples, hands a copy of
the latest window to the fitting thread through a latest-wins queue (:mod:`.fitqueue`). The
thread runs ``process(window)`` (fits, validation, change detection: :mod:`.tracker`) and
leaves results for ``drain`` (the publishing side). Nothing on the subscription path waits for
a fit, and every buffer has a fixed size. ``process`` may be a
:class:`~.workerproc.ProcessWorker`: the thread then only ships the window to a worker
process and waits (without holding the GIL) for its result, so the fits use a core of
their own; ``close`` is called by :meth:`OnlineEngine.stop`.

Counters (:class:`EngineStats`): ``samples_received`` = aligned samples that reached the
engine, ``samples_dropped`` = those that could not be stored (non-finite values: nothing is
invented), ``samples_missing`` = stamps missing from the sample grid (lost upstream),
``unaligned``/``out_of_order``/``duplicates`` = messages, ``clock_restarts``/``rate_changes``
= how often the input's clock started again or its rate changed (:class:`StampAligner`),
``windows_fitted``/``skipped``/``failed`` = windows; fit latency = from the moment a window
is due to the moment its result is ready; ``fit_cpu_s`` = CPU spent on fits (the worker
process's included).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Generic, TypeVar

import numpy as np

from ..errors import DataError
from .fitqueue import FitWorker, LatestQueue
from .inputs import SPEED_SOURCES, InputAligner
from .streaming import SIGNALS, Sample
from .windows import Window, WindowScheduler

R = TypeVar("R")


@dataclass(frozen=True)
class EngineConfig:
    """Data-path settings (the identifier node's parameters of the same names)."""

    window: int = 1000
    hop: int = 250
    history: int = 0
    queue_size: int = 1
    sample_rate_hz: float = 0.0  # 0 = read from the stamps
    tolerance_s: float = 0.0  # 0 = half a sample period
    max_results: int = 256
    speed_source: str = "auto"  # measured, derived from position, or auto (what arrives)

    def __post_init__(self) -> None:
        if self.window < 2 or self.hop < 1 or self.history < 0:
            raise DataError(f"need window >= 2, hop >= 1 (got {self.window}, {self.hop})")
        if self.queue_size < 1 or self.max_results < 1:
            raise DataError("queue_size and max_results must be >= 1")
        if not (math.isfinite(self.sample_rate_hz) and self.sample_rate_hz >= 0):
            raise DataError(f"sample_rate_hz must be >= 0 (0 = from stamps), got "
                            f"{self.sample_rate_hz}")
        if not (math.isfinite(self.tolerance_s) and self.tolerance_s >= 0):
            raise DataError(f"tolerance_s must be >= 0, got {self.tolerance_s}")
        if self.speed_source not in SPEED_SOURCES:
            raise DataError(f"speed_source must be one of {', '.join(SPEED_SOURCES)}, got "
                            f"'{self.speed_source}'")


@dataclass(frozen=True)
class EngineStats:
    """Counters of the data path and the fitting thread (see the module docstring)."""

    samples_received: int
    samples_dropped: int
    samples_missing: int
    gaps: int
    messages: int
    unaligned: int
    out_of_order: int
    duplicates: int
    clock_restarts: int
    rate_changes: int
    windows_due: int
    windows_fitted: int
    windows_skipped: int
    windows_failed: int
    windows_pending: int
    fit_cpu_s: float
    fit_latency_p50_ms: float | None
    fit_latency_p99_ms: float | None

    def to_dict(self) -> dict[str, float | int | None]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class WindowError:
    """A window whose processing failed (e.g. insufficient excitation): reported, not fatal."""

    seq: int
    start_stamp: float
    end_stamp: float
    error: str


class OnlineEngine(Generic[R]):
    """Aligner + window ring + latest-wins queue + fitting thread around ``process``."""

    def __init__(self, config: EngineConfig, process: Callable[[Window], R],
                 signals: Sequence[str] = SIGNALS,
                 speed_expected: Callable[[], bool] | None = None) -> None:
        self.config = config
        self._process = process
        fs = config.sample_rate_hz
        self.aligner = InputAligner(
            signals, config.speed_source,
            tolerance_ns=round(config.tolerance_s * 1e9) if config.tolerance_s else None,
            period_ns=round(1e9 / fs) if fs else None, speed_expected=speed_expected)
        self.scheduler = WindowScheduler(config.window, config.hop, config.history,
                                         len(signals), signals)
        self._queue: LatestQueue[Window] = LatestQueue(config.queue_size)
        self._results: deque[R | WindowError] = deque(maxlen=config.max_results)
        self._lock = threading.Lock()
        self._dropped = 0
        self._worker: FitWorker[Window, R] = FitWorker(
            self._queue, process, self._on_result, self._on_error,
            latency_of=lambda w: w.due_monotonic, name="pmsm-identifier-fit",
            cpu_clock=self._cpu_clock(process))
        self._started = False

    @staticmethod
    def _cpu_clock(process: Callable[[Window], R]) -> Callable[[], float]:
        worker_cpu = getattr(process, "cpu_s", None)
        if not isinstance(worker_cpu, float):
            return time.thread_time
        return lambda: time.thread_time() + float(getattr(process, "cpu_s", 0.0))

    # -- lifecycle --------------------------------------------------------------------
    def start(self) -> None:
        if not self._started:
            self._worker.start()
            self._started = True

    def stop(self, timeout: float = 30.0) -> None:
        """Fit what is queued (at most ``queue_size`` windows), then stop the thread (and
        close ``process`` if it has a ``close``, e.g. a worker process)."""
        if self._started:
            self._worker.stop(timeout)
        close = getattr(self._process, "close", None)
        if callable(close):
            close()

    def hand_over_ahead(self, windows: int) -> None:
        """Let the fitting thread hand up to ``windows`` windows at once to a ``process``
        that computes elsewhere (a worker process), so it never waits for the hand-over
        between two fits (1, the default: one at a time). A window handed over is fitted,
        never skipped: more than 1 suits a caller that publishes nothing while a window
        waits (the stepped sim clock), not a live input that may outrun the fits."""
        if windows < 1:
            raise DataError(f"windows handed over at once must be >= 1, got {windows}")
        self._worker.ahead = windows

    # -- subscription path ------------------------------------------------------------
    def push(self, signal: str, stamp_ns: int, value: float) -> None:
        """One message of one signal."""
        self._store(self.aligner.push(signal, stamp_ns, value))

    def push_sample(self, stamp_ns: int, values: Sequence[float]) -> None:
        """One already aligned sample (JointState layout)."""
        self._store(self.aligner.push_sample(stamp_ns, values))

    def flush(self) -> None:
        """End of stream: emit what the aligner still holds."""
        self._store(self.aligner.flush())

    def _store(self, samples: list[Sample]) -> None:
        for s in samples:
            if not all(map(math.isfinite, s.values)):
                self._dropped += 1
                continue
            window = self.scheduler.push(s)
            if window is not None:
                if self.aligner.speed_derived:
                    window = replace(window, speed_derived=True)
                self._queue.put(window)

    # -- results ----------------------------------------------------------------------
    def _on_result(self, window: Window, result: R) -> None:
        with self._lock:
            self._results.append(result)

    def _on_error(self, window: Window, exc: Exception) -> None:
        err = WindowError(window.seq, window.start_stamp, window.end_stamp,
                          f"{type(exc).__name__}: {exc}")
        with self._lock:
            self._results.append(err)

    def drain(self) -> list[R | WindowError]:
        """Results finished since the last call, oldest first."""
        with self._lock:
            out = list(self._results)
            self._results.clear()
        return out

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until the queue is empty and the worker is not fitting (tests, shutdown)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            ws = self._worker.stats
            if not len(self._queue) and ws.processed + self._queue.skipped >= self._queue.put_count:
                return True
            time.sleep(0.005)
        return False

    @property
    def idle(self) -> bool:
        """No window waits or is being fitted, and every result has been drained."""
        with self._lock:
            undrained = len(self._results)
        done = self._worker.stats.processed + self._queue.skipped >= self._queue.put_count
        return not len(self._queue) and done and not undrained

    @property
    def windows_waiting(self) -> int:
        """Windows queued for the fitting thread (not counting the one being fitted)."""
        return len(self._queue)

    @property
    def samples_received(self) -> int:
        """Aligned samples so far (cheap; for back-pressure loops)."""
        return self.aligner.samples_emitted

    @property
    def stats(self) -> EngineStats:
        a = self.aligner.stats
        w = self._worker.stats
        lat = np.array(w.latencies_s) * 1e3
        p50, p99 = ((float(np.percentile(lat, 50)), float(np.percentile(lat, 99)))
                    if lat.size else (None, None))
        return EngineStats(
            samples_received=a.samples, samples_dropped=self._dropped,
            samples_missing=a.samples_missing, gaps=a.gaps, messages=a.messages,
            unaligned=a.unaligned, out_of_order=a.out_of_order, duplicates=a.duplicates,
            clock_restarts=a.restarts, rate_changes=a.rate_changes,
            windows_due=self._queue.put_count, windows_fitted=w.processed - w.failed,
            windows_skipped=self._queue.skipped, windows_failed=w.failed,
            windows_pending=len(self._queue), fit_cpu_s=w.cpu_s,
            fit_latency_p50_ms=p50, fit_latency_p99_ms=p99)
