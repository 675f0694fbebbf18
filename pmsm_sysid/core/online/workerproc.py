"""A processor in a worker process of its own: fits off the caller's GIL (standard library).

:class:`ProcessWorker` builds one object in one dedicated worker process
(``factory(*args)``, e.g. a :class:`~.tracker.WindowTracker`) and applies one of its methods
to each item sent to it, in the order sent, so a processor that keeps state between items
(the previous model, the change detector) sees exactly what it would see in the caller's
thread. Items and results are pickled (numpy arrays bit for bit), so the numbers are those of
the same code run in-process.

The worker is a ``concurrent.futures.ProcessPoolExecutor`` with one process started by the
``forkserver`` method: the process is forked from a clean server process, never from the
caller (a process running rclpy has middleware threads that a fork would copy in an unknown
state). It is started and warmed up (its modules imported) when the worker is created, not
when the first item is due. If the process dies (killed, out of memory), the item fails
with :class:`WorkerDied`, the processor is rebuilt in a new process (its state starts
again), and the next item goes there. A worker whose owner is gone (killed with SIGKILL,
so it could not say so) ends itself within half a second. A worker ignores SIGINT: its
owner decides when it stops (a terminal's Ctrl-C reaches every process of the foreground
group, and a worker interrupted mid-item would only print a traceback).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Generic, TypeVar

from ..errors import PmsmSysidError
from .fitqueue import Ticket

T = TypeVar("T")
R = TypeVar("R")

START_METHOD = "forkserver"
#: modules the fork server imports once, so each new worker starts with them loaded: the
#: identifier's fits and the GFRF analysis need nothing else (neither scipy.signal nor
#: scipy.stats, about half a second more: see core.recording.spectra), so their first item
#: is not slowed by an import, which would be long enough to skip the next window
PRELOAD = ("numpy", "scipy.linalg", "pmsm_sysid.core.online.tracker",
           "pmsm_sysid.core.frequency.analysis")

_state: dict[str, Any] = {}


class WorkerDied(PmsmSysidError):
    """The worker process ended while processing an item (its state is rebuilt)."""


def owner_alive(pid: int) -> bool:
    """True while process ``pid`` runs (a zombie, killed but not yet reaped, is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:
            return True
        return True


def _watch(owner: int, period_s: float = 0.5) -> None:
    """End this worker when its owner is gone (a SIGKILLed owner cannot tell it)."""
    while owner_alive(owner):
        time.sleep(period_s)
    os._exit(0)


def _build(factory: Callable[..., Any], args: Sequence[Any], method: str | None,
           owner: int, nice: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the owner stops it (module docstring)
    if nice:
        os.nice(nice)
    threading.Thread(target=_watch, args=(owner,), name="owner-watch", daemon=True).start()
    obj = factory(*args)
    _state["fn"] = getattr(obj, method) if method else obj


def _apply(item: Any) -> tuple[Any, float]:
    """Run the processor on one item in the worker; returns (result, CPU seconds)."""
    c0 = time.process_time()
    result = _state["fn"](item)
    return result, time.process_time() - c0


def _ready() -> int:
    return 0


def _context() -> Any:
    return multiprocessing.get_context(START_METHOD)


def start_server(preload: Sequence[str] | None = None) -> None:
    """Start the fork server now (if it is not running), so that its imports (``preload``;
    None: :data:`PRELOAD`, about a second of CPU) run beside the caller's own start-up
    instead of delaying its first worker.

    The server starts with SIGINT blocked, which it and every process forked from it keep:
    a Ctrl-C on the terminal (sent to the whole foreground process group) then stops only
    the caller, which closes its workers, instead of interrupting the server's start-up and
    the workers' with a traceback each. The calling thread blocks SIGINT only while it
    starts the server: a Ctrl-C meanwhile reaches the caller right after.
    """
    ctx = _context()
    ctx.set_forkserver_preload(list(PRELOAD if preload is None else preload))
    from multiprocessing import forkserver, resource_tracker

    # the server's resource tracker first: starting it unblocks SIGINT in the calling thread
    resource_tracker.ensure_running()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # inherited by the server
    try:
        forkserver.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _warm_up(pool: ProcessPoolExecutor) -> None:
    # closed (or broken) before its process started: nothing to warm up
    with contextlib.suppress(RuntimeError, BrokenProcessPool):
        pool.submit(_ready)


class ProcessWorker(Generic[T, R]):
    """``factory(*args)`` in a dedicated worker process; ``worker(item)`` runs ``method``
    of it there on ``item`` and returns the result (exceptions are re-raised here).

    Call from one thread at a time (calls are served in order); :meth:`submit` sends an item
    without waiting for it (a :class:`~.fitqueue.Ticket`). :attr:`cpu_s` adds up the
    worker's CPU time per item; :meth:`close` ends the process. ``nice`` > 0 lowers the
    worker's scheduling priority (work that may fall behind and skip, e.g. analyses).
    """

    def __init__(self, factory: Callable[..., Any], args: Sequence[Any] = (),
                 method: str | None = None, nice: int = 0) -> None:
        self._spec = (factory, tuple(args), method, os.getpid(), int(nice))
        self._lock = threading.Lock()
        self._cpu = 0.0
        self.restarts = 0
        self._closed = False
        self._pool = self._start()

    def _start(self) -> ProcessPoolExecutor:
        start_server()  # returns at once if it runs (else: started deaf to Ctrl-C)
        pool = ProcessPoolExecutor(max_workers=1, mp_context=_context(),
                                   initializer=_build, initargs=self._spec)
        # start and warm up the process now, not at the first item, from a thread: the
        # fork server may still be importing its modules (start_server), and the caller
        # need not wait for that (an item sent meanwhile waits for the process)
        threading.Thread(target=_warm_up, args=(pool,), name="worker-start",
                         daemon=True).start()
        return pool

    def __call__(self, item: T) -> R:
        return self.submit(item).collect()  # type: ignore[no-any-return]

    def submit(self, item: T) -> Ticket:
        """Send ``item`` to the worker now; the ticket's ``collect()`` returns its result
        (items are processed one after the other, in the order sent)."""
        with self._lock:
            if self._closed:
                raise WorkerDied("the worker process was closed")
            pool = self._pool
        future: Future[tuple[R, float]] = pool.submit(_apply, item)
        return Ticket(future, lambda: self._collect(pool, future))

    def _collect(self, pool: ProcessPoolExecutor, future: Future[tuple[R, float]]) -> R:
        try:
            result, cpu = future.result()
        except BrokenProcessPool as exc:
            self._restart(pool)
            raise WorkerDied(f"the worker process ended ({exc}); it was restarted") from exc
        with self._lock:
            self._cpu += cpu
        return result

    def _restart(self, broken: ProcessPoolExecutor) -> None:
        with self._lock:
            if self._closed or broken is not self._pool:
                return
            broken.shutdown(wait=False, cancel_futures=True)
            self._pool = self._start()
            self.restarts += 1

    @property
    def cpu_s(self) -> float:
        """CPU seconds the worker process spent on items so far."""
        with self._lock:
            return self._cpu

    @property
    def pid(self) -> int | None:
        """The worker process's id (None before it started)."""
        procs = getattr(self._pool, "_processes", None) or {}
        return next(iter(procs), None)

    def close(self) -> None:
        """End the worker process (waits for the item in progress); idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            pool = self._pool
        pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> ProcessWorker[T, R]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
