"""Hand-over from the subscription path to the fitting thread (pure Python, thread-safe).

:class:`LatestQueue` is bounded and latest-wins: when fits cannot keep up, the oldest waiting
window is skipped and counted, so memory stays fixed and the newest data are fitted first.
:class:`FitWorker` is the thread that takes items off the queue and runs the fits, so the
subscription path never waits for a fit; it records the thread's CPU time and the latency
from "window due" to "result ready".
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

from ..errors import DataError

T = TypeVar("T")
R = TypeVar("R")


class LatestQueue(Generic[T]):
    """Bounded FIFO where ``put`` never blocks: when full the oldest item is skipped."""

    def __init__(self, maxsize: int = 1) -> None:
        if maxsize < 1:
            raise DataError(f"queue size must be >= 1, got {maxsize}")
        self._items: deque[T] = deque()
        self._maxsize = maxsize
        self._cond = threading.Condition()
        self._closed = False
        self.skipped = 0
        self.put_count = 0

    def put(self, item: T) -> None:
        with self._cond:
            if len(self._items) >= self._maxsize:
                self._items.popleft()
                self.skipped += 1
            self._items.append(item)
            self.put_count += 1
            self._cond.notify()

    def get(self, timeout: float | None = None) -> T | None:
        """Next item, or None on timeout or once closed and empty."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._items or self._closed, timeout):
                return None
            return self._items.popleft() if self._items else None

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        with self._cond:
            return self._closed and not self._items

    def __len__(self) -> int:
        with self._cond:
            return len(self._items)


@dataclass(frozen=True)
class WorkerStats:
    """What the fitting thread did: counts, CPU seconds of the thread, latencies (s)."""

    processed: int
    failed: int
    cpu_s: float
    latencies_s: tuple[float, ...]


class FitWorker(Generic[T, R]):
    """A thread applying ``fn`` to queued items; results (or errors) go to ``on_result``.

    ``fn`` runs off the caller's thread, so the subscription path only pays for the copy of
    a window. Exceptions are passed to ``on_error`` and counted, never kill the thread.
    ``cpu_clock`` measures the CPU an item costs (default: this thread's CPU time; when
    ``fn`` hands the item to a worker process, a clock that adds the worker's CPU).
    """

    def __init__(self, queue: LatestQueue[T], fn: Callable[[T], R],
                 on_result: Callable[[T, R], None],
                 on_error: Callable[[T, Exception], None] | None = None,
                 latency_of: Callable[[T], float] | None = None,
                 name: str = "fit-worker", keep_latencies: int = 4096,
                 cpu_clock: Callable[[], float] = time.thread_time) -> None:
        self._queue, self._fn = queue, fn
        self._cpu_clock = cpu_clock
        self._on_result, self._on_error = on_result, on_error
        self._latency_of = latency_of
        self._lat: deque[float] = deque(maxlen=keep_latencies)
        self._processed = self._failed = 0
        self._cpu = 0.0
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Close the queue and wait for the current item to finish."""
        self._queue.close()
        if self._thread.is_alive():
            self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    @property
    def stats(self) -> WorkerStats:
        with self._lock:
            return WorkerStats(self._processed, self._failed, self._cpu, tuple(self._lat))

    def _loop(self) -> None:
        while True:
            item = self._queue.get(timeout=0.5)
            if item is None:
                if self._queue.closed:
                    return
                continue
            c0 = self._cpu_clock()
            try:
                result = self._fn(item)
            except Exception as exc:  # reported, counted; the thread must keep running
                with self._lock:
                    self._failed += 1
                if self._on_error is not None:
                    self._on_error(item, exc)
            else:
                self._on_result(item, result)
            with self._lock:
                self._processed += 1
                self._cpu += self._cpu_clock() - c0
                if self._latency_of is not None:
                    self._lat.append(time.monotonic() - self._latency_of(item))

