"""Hand-over from the subscription path to the fitting thread (pure Python, thread-safe).

:class:`LatestQueue` is bounded and latest-wins: when fits cannot keep up, the oldest waiting
window is skipped and counted, so memory stays fixed and the newest data are fitted first.
:class:`FitWorker` is the thread that takes items off the queue and runs the fits, so the
subscription path never waits for a fit; it records the thread's CPU time and the latency
from "window due" to "result ready". With ``ahead`` > 1 and a processor that computes
elsewhere (``submit`` returns a :class:`Ticket`, e.g. a worker process), the thread hands the
next item over while the previous one is still being computed, so the worker never waits
for the hand-over between two items; results are still delivered one by one, in order.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

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
        self._woken = False
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
        """Next item, or None on timeout, on :meth:`wake`, or once closed and empty."""
        with self._cond:
            ready = self._cond.wait_for(lambda: self._items or self._closed or self._woken,
                                        timeout)
            self._woken = False
            if not ready:
                return None
            return self._items.popleft() if self._items else None

    def wake(self) -> None:
        """Return a waiting :meth:`get` now (with an item if one is there, else None)."""
        with self._cond:
            self._woken = True
            self._cond.notify_all()

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
class Ticket:
    """An item handed to a processor that computes it elsewhere: ``future`` is done when
    the result is there; ``collect()`` returns it (or raises the item's error) in the
    caller's thread, where the processor can also account for it (CPU, restarts)."""

    future: Future[Any]
    collect: Callable[[], Any]


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

    ``ahead`` (settable at any time): how many items may be handed over at once when ``fn``
    also has ``submit(item) -> Ticket``; 1 (the default) waits for each result before
    taking the next item off the queue. A taken item is never skipped, so more than 1 only
    suits a caller that feeds no more than the worker takes (e.g. a stepped simulation).
    """

    def __init__(self, queue: LatestQueue[T], fn: Callable[[T], R],
                 on_result: Callable[[T, R], None],
                 on_error: Callable[[T, Exception], None] | None = None,
                 latency_of: Callable[[T], float] | None = None,
                 name: str = "fit-worker", keep_latencies: int = 4096,
                 cpu_clock: Callable[[], float] = time.thread_time, ahead: int = 1) -> None:
        self._queue, self._fn = queue, fn
        self.ahead = ahead
        self._cpu_clock = cpu_clock
        self._on_result, self._on_error = on_result, on_error
        self._latency_of = latency_of
        self._lat: deque[float] = deque(maxlen=keep_latencies)
        self._processed = self._failed = 0
        self._cpu = self._mark = 0.0
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
        pending: deque[tuple[T, Ticket]] = deque()
        while True:
            submit = getattr(self._fn, "submit", None) if self.ahead > 1 else None
            if pending and (submit is None or len(pending) >= self.ahead
                            or pending[0][1].future.done()):
                self._collect(*pending.popleft())  # the oldest: waits for it if need be
                continue
            item = self._queue.get(timeout=0.5)
            if item is None:
                if self._queue.closed and not pending:
                    return
                continue
            if submit is None:
                self._run(item)
            else:
                self._hand_over(item, submit, pending)

    def _run(self, item: T) -> None:
        """Process one item here and deliver its result (``ahead`` 1)."""
        c0 = self._cpu_clock()
        self._deliver(item, lambda: self._fn(item))
        self._done(item, self._cpu_clock() - c0)

    def _hand_over(self, item: T, submit: Callable[[T], Ticket],
                   pending: deque[tuple[T, Ticket]]) -> None:
        if not pending:
            self._mark = self._cpu_clock()  # CPU counts from the first item handed over
        try:
            ticket = submit(item)
        except Exception as exc:
            self._failed_item(item, exc)
            self._done(item, 0.0)
            return
        ticket.future.add_done_callback(lambda _: self._queue.wake())
        pending.append((item, ticket))

    def _collect(self, item: T, ticket: Ticket) -> None:
        """Deliver a handed-over item's result; its CPU is what passed since the previous
        delivery (items overlap, so each interval is counted once)."""
        self._deliver(item, ticket.collect)
        now = self._cpu_clock()
        cpu, self._mark = now - self._mark, now
        self._done(item, cpu)

    def _deliver(self, item: T, result_of: Callable[[], R]) -> None:
        """``on_result(item, result_of())``, or ``on_error`` with what it raised."""
        try:
            result = result_of()
        except Exception as exc:  # reported, counted; the thread must keep running
            self._failed_item(item, exc)
        else:
            self._on_result(item, result)

    def _failed_item(self, item: T, exc: Exception) -> None:
        with self._lock:
            self._failed += 1
        if self._on_error is not None:
            self._on_error(item, exc)

    def _done(self, item: T, cpu_s: float) -> None:
        with self._lock:
            self._processed += 1
            self._cpu += cpu_s
            if self._latency_of is not None:
                self._lat.append(time.monotonic() - self._latency_of(item))
