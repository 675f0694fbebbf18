"""Where the fleet's work runs: a Dask distributed cluster (``dask.distributed``).

Either a local cluster of worker processes started here (one thread each: the fits are
numpy work that holds the interpreter), or an existing cluster reached through its scheduler
address (``tcp://HOST:PORT``, started with ``dask scheduler`` and ``dask worker``), or a
``Client`` the caller already holds. The same code submits the work to each.
"""

from __future__ import annotations

import logging
import re
import signal
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from ..core.errors import DependencyError, OptionError

if TYPE_CHECKING:
    from dask.distributed import Client

    from .inputs import Unit

EXTRA = "pip install '.[fleet]' (in the pmsm_sysid source directory)"
#: Dask settings of the local cluster's workers. The statistical profiler (a sample of every
#: thread's stack each 10 ms) off: on rows of pure Python and numpy it cost about a fifth of
#: a worker's CPU time. And the environment the nanny gives its worker without Dask's
#: ``MALLOC_TRIM_THRESHOLD_``: that setting fixes glibc's mmap threshold, so every array of
#: more than 128 kB is mapped and unmapped anew (ten times the page faults; a row's system
#: time 0.04 -> 0.36 s); None unsets it. A cluster of your own takes the same settings from
#: its workers' Dask configuration (docs/fleet.md). And the event loops' housekeeping less
#: often: the blocked-loop check every 1 s (not 20 ms), each nanny's look at its worker's
#: memory every 1 s (not 100 ms), the system monitor every 5 s (not 0.5 s) -- an idle
#: cluster of two workers cost 1.8 s of CPU per 30 s with Dask's intervals, 0.2 s with
#: these, in the scheduler, nannies and workers together.
#: And the workers forked from one fork server (``forkserver``, not Dask's ``spawn``): the
#: server imports Dask, numpy and what a row needs once (:data:`ROW_MODULES`), so each
#: worker starts with them loaded instead of importing them itself (about 1.5 s of CPU per
#: worker; its first row no longer waits for them). The server is a clean process started
#: for this (never a fork of the caller, whatever threads it runs).
WORKER_CONFIG = {
    "distributed.worker.multiprocessing-method": "forkserver",
    "distributed.worker.profile.enabled": False,
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
}
#: How long a scheduler address may take to answer, and workers to show up (s).
CONNECT_TIMEOUT_S = 5.0
WORKERS_TIMEOUT_S = 10.0


def require_extra() -> None:
    """DependencyError naming the ``[fleet]`` extra unless Dask distributed and pyarrow
    import."""
    missing = []
    for module, package in (("dask.distributed", "dask[distributed]"), ("pyarrow", "pyarrow")):
        try:
            __import__(module)
        except ImportError:
            missing.append(package)
    if missing:
        raise DependencyError(f"fleet needs {' and '.join(missing)}, not installed here: "
                              f"{EXTRA}")


def _probe() -> str:
    """Run on each worker: the package version it would analyse with."""
    import pmsm_sysid

    return pmsm_sysid.__version__


def check_workers(client: Client, where: str, timeout_s: float = WORKERS_TIMEOUT_S) -> int:
    """The number of workers, after checking there is one and each runs this package's
    version (a worker without it would fail every recording)."""
    import pmsm_sysid

    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except TimeoutError as exc:
        raise OptionError(f"{where}: no worker joined within {timeout_s:g} s (start one with "
                          "'dask worker ADDRESS')") from exc
    try:
        versions: Mapping[str, Any] = client.run(_probe)
    except Exception as exc:
        raise OptionError(f"{where}: a worker cannot run pmsm_sysid ({type(exc).__name__}: "
                          f"{' '.join(str(exc).split())}); install it there: {EXTRA}") from exc
    wrong = {w: v for w, v in versions.items() if v != pmsm_sysid.__version__}
    if wrong:
        w, v = next(iter(wrong.items()))
        raise OptionError(f"{where}: worker {w} runs pmsm_sysid {v}, this is "
                          f"{pmsm_sysid.__version__}: install the same version on every worker")
    return len(versions)


_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ws|wss|ucx)://)?(\[[0-9A-Fa-f:.]+\]|[^:/\s\[\]]+):(\d{1,5})$")


def check_address(address: str) -> str:
    """A scheduler address ``tcp://HOST:PORT`` (or tls://, ws://, wss://, ucx://, or no
    scheme); OptionError otherwise."""
    m = _ADDRESS.match(address) if isinstance(address, str) else None
    if m is None or not 0 < int(m.group(2)) < 65536:
        raise OptionError(f"--scheduler {address}: not a scheduler address (expected "
                          "tcp://HOST:PORT, as 'dask scheduler' prints)")
    return address


def connect(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> Client:
    """A client of the cluster whose scheduler listens at ``address``; OptionError (one
    line) when it does not answer within ``timeout_s``."""
    from dask.distributed import Client

    check_address(address)
    try:
        client = Client(address, timeout=timeout_s, set_as_default=False)
    except Exception as exc:  # OSError (timeout, refused), ValueError (malformed address)
        raise OptionError(f"--scheduler {address}: no Dask scheduler answers there within "
                          f"{timeout_s:g} s ({' '.join(str(exc).split())})") from exc
    try:
        check_workers(client, f"--scheduler {address}")
    except BaseException:
        client.close()
        raise
    return client


def _preload_rows() -> None:
    """Have the fork server the local workers start from import what a row needs, and
    start it (SIGINT blocked in it and its workers), when the configured start method is
    ``forkserver`` and the server is not running yet (a running one keeps its imports: the
    workers then import the rest themselves)."""
    import dask
    from distributed.utils import get_mp_context

    from ..api.fleet_row import ROW_MODULES
    from ..core.online.workerproc import start_server

    get_mp_context()  # Dask chooses its own preload here, once: ours replaces it
    if dask.config.get("distributed.worker.multiprocessing-method") == "forkserver":
        start_server(["distributed", "numpy", *ROW_MODULES])  # deaf to Ctrl-C (docstring)


@contextmanager
def _interrupt_held(interrupted: list[int]) -> Iterator[None]:
    """While active (in the main thread), a SIGINT is noted in ``interrupted`` instead of
    raising: a cluster interrupted while its workers start leaves them starting against a
    parent that has gone, each with a traceback; the caller stops once it has started."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is None:  # a handler set outside Python
        yield
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: interrupted.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def local_cluster(workers: int) -> Iterator[Client]:
    """A cluster of ``workers`` local worker processes, one thread each (its diagnostics
    page on a free port, never a fixed one another cluster may hold); closed on exit. The
    workers run without Dask's statistical profiler and start forked from a server that
    imported what a row needs (:data:`WORKER_CONFIG`)."""
    import dask
    from dask.distributed import Client, LocalCluster

    interrupted: list[int] = []
    try:
        with dask.config.set(WORKER_CONFIG), _interrupt_held(interrupted):
            _preload_rows()
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.ERROR)
    except Exception as exc:
        raise OptionError(
            f"the local Dask cluster of {workers} worker(s) did not start "
            f"({type(exc).__name__}: {' '.join(str(exc).split())}); a Python script that "
            "runs a fleet must do so under 'if __name__ == \"__main__\":' (its worker "
            "processes import the script)") from exc
    if interrupted:  # Ctrl-C while it started: now that it has, close it and stop
        cluster.close()
        raise KeyboardInterrupt
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def run(client: Client, units: Sequence[Unit], task: Callable[..., dict[str, Any]],
        options: Mapping[str, Any], on_row: Callable[[dict[str, Any]], None],
        on_failure: Callable[[Unit, BaseException], dict[str, Any]]) -> None:
    """Submit ``task(unit.path, **unit.row_arguments(), **options)`` for every unit and
    hand each row to ``on_row`` as it finishes (any order). A task that raises (its worker
    died) gives ``on_failure(unit, exc)``'s row. On any exit (Ctrl-C too) the tasks not
    finished are cancelled."""
    from dask.distributed import as_completed

    pending: dict[Any, Unit] = {}
    for u in units:
        fut = client.submit(task, u.path, pure=False, **u.row_arguments(), **options)
        pending[fut] = u
    try:
        for fut in as_completed(list(pending), loop=client.loop):
            unit = pending.pop(fut)
            try:
                row = fut.result()
            except Exception as exc:  # the task itself never raises: its worker died
                row = on_failure(unit, exc)
            fut.release()
            on_row(row)
    finally:
        if pending:
            client.cancel(list(pending))
