"""Fits in a worker process (core/workerproc.py): same results as in-process, in order,
failures reported, a dead worker replaced. Completion conditions only (no timing)."""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable
from pathlib import Path

import pytest
from narx_systems import QUADRATIC, simulate, white_input

from pmsm_sysid.core.online.engine import EngineConfig, OnlineEngine, WindowError
from pmsm_sysid.core.online.streaming import NS_PER_S
from pmsm_sysid.core.online.tracker import OutputConfig, TrackerConfig, WindowResult, WindowTracker
from pmsm_sysid.core.online.workerproc import ProcessWorker, WorkerDied
from pmsm_sysid.core.selection.identify import FitConfig
from pmsm_sysid.core.terms.model import Structure

CONFIG = TrackerConfig(outputs=(OutputConfig("speed", FitConfig(
    structure=Structure(ny=2, nu=2, degree=2), n_terms=5)),), window=400, hop=200)


def _results(process: object, n: int = 1600,
             ahead: int = 1) -> list[WindowResult | WindowError]:
    """Feed the engine one hop at a time (the latest-wins queue then skips nothing); with
    ``ahead`` > 1, all at once into a queue that holds every window, handed over ``ahead``
    at a time."""
    engine: OnlineEngine[WindowResult] = OnlineEngine(
        EngineConfig(window=400, hop=200, history=CONFIG.history, queue_size=n // 200),
        process)  # type: ignore[arg-type]
    engine.hand_over_ahead(ahead)
    engine.start()
    u = white_input(n, seed=7)
    y = simulate(QUADRATIC, u, noise_std=1e-3, seed=7)
    try:
        for k in range(n):
            engine.push_sample(NS_PER_S + k * 2_000_000, (u[k], y[k], 0.0))
            if (k + 1) % 200 == 0 and ahead == 1:
                assert engine.wait_idle(60)
        assert engine.wait_idle(60)
        stats = engine.stats
    finally:
        engine.stop()
    assert stats.windows_skipped == 0 and stats.windows_failed == 0
    assert stats.fit_cpu_s > 0
    return engine.drain()


def _timeless(r: WindowResult | WindowError) -> str:
    """The result without its timings, as JSON (NaN equals NaN there)."""
    assert isinstance(r, WindowResult)
    models = [{k: v for k, v in m.items() if k not in ("fit_time_ms", "timing_ms")}
              for m in r.models]
    return json.dumps([r.seq, models, r.validations, r.changes, r.decisions, r.errors],
                      sort_keys=True)


def test_the_tracker_in_a_worker_process_gives_the_in_process_results() -> None:
    here = _results(WindowTracker(CONFIG).process)
    worker = ProcessWorker[object, WindowResult](WindowTracker, (CONFIG,), method="process")
    there = _results(worker)  # the engine's stop() closes the worker
    assert len(here) == len(there) == 6
    assert [_timeless(r) for r in here] == [_timeless(r) for r in there]
    assert any(r.validations for r in there if isinstance(r, WindowResult))  # state carried


def test_windows_handed_over_ahead_give_the_in_process_results_in_order() -> None:
    """Two windows at the worker at once (the next sent while one is fitted): the same
    results, in the same order, each window fitted once."""
    here = _results(WindowTracker(CONFIG).process)
    worker = ProcessWorker[object, WindowResult](WindowTracker, (CONFIG,), method="process")
    there = _results(worker, ahead=2)
    assert [_timeless(r) for r in here] == [_timeless(r) for r in there]


def test_items_submitted_together_come_back_in_order_and_a_death_is_reported() -> None:
    with ProcessWorker[object, WindowResult](WindowTracker, (CONFIG,),
                                             method="process") as worker:
        first, second = worker.submit(None), worker.submit(None)
        for ticket in (first, second):  # not windows: the worker's errors, raised here
            with pytest.raises(AttributeError):
                ticket.collect()
        pid = worker.pid
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        with pytest.raises(WorkerDied):
            worker.submit(None).collect()
        assert worker.restarts == 1


def test_worker_runs_elsewhere_reraises_and_replaces_a_dead_process() -> None:
    with ProcessWorker[object, WindowResult](WindowTracker, (CONFIG,),
                                             method="process") as worker:
        with pytest.raises(AttributeError):
            worker(None)  # not a window: the error of the worker, raised here
        pid = worker.pid
        assert pid is not None and pid != os.getpid()
        os.kill(pid, signal.SIGKILL)
        with pytest.raises(WorkerDied):
            worker(None)
        assert worker.restarts == 1
        with pytest.raises(AttributeError):  # the new process serves the next item
            worker(None)
        assert worker.pid not in (None, pid)
    with pytest.raises(WorkerDied):
        worker(None)  # closed


def _sigint_ignored(_: object) -> bool:
    """In the worker: is SIGINT ignored?"""
    return signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def _sigint_probe() -> Callable[[object], bool]:
    return _sigint_ignored


def test_a_terminals_ctrl_c_is_for_the_owner_not_the_worker() -> None:
    """A Ctrl-C reaches every process of the terminal's process group: the worker ignores
    it (its owner closes it), so it is not interrupted mid-item with a traceback, and it
    still serves items after one."""
    with ProcessWorker[object, bool](_sigint_probe) as worker:
        assert worker(None) is True
        pid = worker.pid
        assert pid is not None
        os.kill(pid, signal.SIGINT)
        assert worker(None) is True and worker.pid == pid and worker.restarts == 0


GATED = '''
import pathlib, time
gate = pathlib.Path({gate!r})
deadline = time.monotonic() + 120.0
while not gate.exists() and time.monotonic() < deadline:
    time.sleep(0.01)
pathlib.Path({done!r}).touch()
'''

SCRIPT = '''
import operator, pathlib, sys
from pmsm_sysid.core.online import workerproc

workerproc.PRELOAD = (*workerproc.PRELOAD, "gated_preload")
workerproc.start_server()
worker = workerproc.ProcessWorker(operator.itemgetter, (1,))
print("fork server done on return:", pathlib.Path(sys.argv[2]).exists(), flush=True)
pathlib.Path(sys.argv[1]).touch()
print("item:", worker([3, 4]), flush=True)
worker.close()
'''


def test_a_worker_is_made_without_waiting_for_the_fork_servers_imports(
        tmp_path: Path) -> None:
    """start_server starts the imports early; a worker made meanwhile returns at once (its
    process starts when the imports are done, and an item sent meanwhile waits for it)."""
    import subprocess
    import sys

    gate, done = tmp_path / "gate", tmp_path / "done"
    (tmp_path / "gated_preload.py").write_text(
        GATED.format(gate=str(gate), done=str(done)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])])}
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(gate), str(done)], env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["fork server done on return: False", "item: 4"]
