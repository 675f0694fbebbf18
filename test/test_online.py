"""Streaming alignment, windowing and hand-over of the online identifier (core/online.py)."""

from __future__ import annotations

import threading
import time
from itertools import pairwise

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.online.fitqueue import FitWorker, LatestQueue, Ticket
from pmsm_sysid.core.online.streaming import SIGNALS, Sample, StampAligner
from pmsm_sysid.core.online.windows import Window, WindowScheduler

PERIOD = 2_000_000  # 500 Hz in ns


def _messages(n: int, t0: int = 0, jitter: float = 0.0, seed: int = 0):
    """(signal, stamp, value) for n samples; value encodes (sample, signal) for checking."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        for j, s in enumerate(SIGNALS):
            dj = int(rng.uniform(-jitter, jitter) * PERIOD) if jitter else 0
            out.append((s, t0 + k * PERIOD + dj, 10.0 * k + j))
    return out


def _run(aligner: StampAligner, msgs) -> list[Sample]:
    out: list[Sample] = []
    for s, t, v in msgs:
        out.extend(aligner.push(s, t, v))
    return out


def _check_in_order(samples: list[Sample], first_index: int = 0) -> None:
    for i, smp in enumerate(samples):
        k = smp.index - first_index
        assert smp.values == (10.0 * k, 10.0 * k + 1, 10.0 * k + 2)
        if i:
            assert smp.index > samples[i - 1].index


def test_exact_stamps_align_every_sample_and_read_the_period() -> None:
    al = StampAligner()
    samples = _run(al, _messages(200)) + al.flush()
    assert len(samples) == 200
    assert [s.index for s in samples] == list(range(200))
    _check_in_order(samples)
    assert al.period_ns == PERIOD and al.tolerance_ns == PERIOD // 2
    st_ = al.stats
    assert (st_.messages, st_.samples, st_.unaligned, st_.gaps) == (600, 200, 0, 0)


def test_absolute_index_follows_the_stamp_grid() -> None:
    """Index = stamp / period, so another process seeing a later start agrees on indices."""
    al = StampAligner()
    samples = _run(al, _messages(50, t0=1000 * PERIOD))
    assert samples[0].index == 1000
    _check_in_order(samples, first_index=1000)


def test_jittered_stamps_within_tolerance_are_joined() -> None:
    al = StampAligner()
    samples = _run(al, _messages(300, t0=10 * PERIOD, jitter=0.2, seed=3)) + al.flush()
    assert len(samples) == 300
    _check_in_order(samples, first_index=samples[0].index)
    assert al.stats.unaligned == 0 and al.stats.gaps == 0


def test_lost_message_is_counted_unaligned_and_as_a_gap() -> None:
    msgs = [m for m in _messages(100) if not (m[0] == "speed" and m[1] == 40 * PERIOD)]
    al = StampAligner()
    samples = _run(al, msgs) + al.flush()
    assert len(samples) == 99
    assert 40 not in [s.index for s in samples]
    st_ = al.stats
    assert st_.unaligned == 2  # thrust and position of sample 40 had no partner
    assert st_.gaps == 1 and st_.samples_missing == 1


def test_duplicates_and_late_messages_are_counted_not_used() -> None:
    msgs = _messages(60)
    msgs.insert(30, ("speed", 9 * PERIOD, -1.0))  # duplicate of an emitted sample
    msgs.append(("thrust", 6 * PERIOD, -2.0))  # long after sample 6 left: out of order
    msgs.insert(3, ("thrust", 0, -3.0))  # repeat while sample 0 is still pending
    al = StampAligner()
    samples = _run(al, msgs) + al.flush()
    assert len(samples) == 60
    _check_in_order(samples)  # the first value was kept, the repeats were not used
    assert al.stats.duplicates == 2 and al.stats.out_of_order == 1


def test_late_message_beyond_tolerance_is_out_of_order() -> None:
    msgs = _messages(60)
    msgs.append(("thrust", 20 * PERIOD + PERIOD // 3, -2.0))  # old stamp, matches nothing
    al = StampAligner()
    _run(al, msgs)  # an unusual step: held until the stream goes on (or ends)
    assert al.stats.out_of_order == 0
    al.flush()
    assert al.stats.out_of_order == 1 and al.stats.duplicates == 0 and al.stats.restarts == 0


def test_interleaving_across_samples_keeps_stamp_order() -> None:
    """Speed of sample k arrives after thrust of k+3: still emitted in order."""
    msgs = _messages(100)
    by_signal = {s: [m for m in msgs if m[0] == s] for s in SIGNALS}
    delayed = by_signal["thrust"][:3]
    for k in range(100):
        if k + 3 < 100:
            delayed.append(by_signal["thrust"][k + 3])
        delayed += [by_signal["speed"][k], by_signal["position"][k]]
    al = StampAligner()
    samples = _run(al, delayed) + al.flush()
    assert [s.index for s in samples] == list(range(100))
    _check_in_order(samples)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 6))
def test_any_bounded_interleaving_is_undone(seed: int, spread: int) -> None:
    """Each topic arrives in order (DDS keeps per-topic order) but the topics drift against
    each other by up to ``spread`` samples: every sample still comes out, in order."""
    msgs = _messages(80)
    rng = np.random.default_rng(seed)
    arrival = {s: np.maximum.accumulate(np.arange(80) + rng.uniform(0, spread, 80))
               for s in SIGNALS}
    keys = [arrival[m[0]][i // 3] + 1e-3 * (i % 3) for i, m in enumerate(msgs)]
    shuffled = [msgs[i] for i in np.argsort(keys, kind="stable")]
    al = StampAligner(period_ns=PERIOD)
    samples = _run(al, shuffled) + al.flush()
    assert [s.index for s in samples] == list(range(80))
    _check_in_order(samples)


def test_a_restarted_clock_is_followed_from_its_new_origin() -> None:
    """A publisher restarted on a clock from zero (a sim restarted): after HOLD_STEPS usual
    steps the order is reset; every sample of the new stream comes out, on its own grid."""
    al = StampAligner()
    first = _run(al, _messages(100, t0=5000 * PERIOD))
    second = _run(al, _messages(100, t0=0)) + al.flush()
    assert len(first) == 100 and len(second) == 100
    assert [s.index for s in second] == list(range(100))
    _check_in_order(second)
    st_ = al.stats
    assert (st_.restarts, st_.out_of_order, st_.duplicates, st_.unaligned) == (1, 0, 0, 0)


@pytest.mark.parametrize("factor", [0.5, 2.0, 5.0])
def test_a_rate_change_gives_a_new_grid_and_breaks_the_run(factor: float) -> None:
    al = StampAligner()
    a = _run(al, [(s, t, v) for s, t, v in _messages(100, t0=100 * PERIOD)])
    new = round(PERIOD / factor)
    t0 = 200 * PERIOD
    later = [(s, t0 + k * new, 10.0 * k + j) for k in range(100)
             for j, s in enumerate(SIGNALS) for t in [0]]
    b = _run(al, later) + al.flush()
    assert len(a) == 100 and len(b) == 100
    assert al.period_ns == new and al.stats.rate_changes == 1 and al.stats.duplicates == 0
    # the first new sample still sits on the old grid (one period after the last); from the
    # second on the indices run on the new grid, not contiguous with the old run
    assert b[0].index == a[-1].index + 1 and b[1].index != b[0].index + 1
    assert all(y.index == x.index + 1 for x, y in pairwise(b[1:]))
    _check_in_order(b[1:], first_index=b[1].index - 1)


def test_one_lost_sample_is_still_a_gap_not_a_rate_change() -> None:
    msgs = [m for m in _messages(100) if m[1] != 50 * PERIOD]
    al = StampAligner()
    out = _run(al, msgs) + al.flush()
    assert len(out) == 99 and al.stats.gaps == 1 and al.stats.samples_missing == 1
    assert al.stats.rate_changes == 0 and al.period_ns == PERIOD


def test_joint_state_layout_pushes_whole_samples() -> None:
    al = StampAligner()
    out = []
    for k in range(20):
        out += al.push_sample(k * PERIOD, (10.0 * k, 10.0 * k + 1, 10.0 * k + 2))
    out += al.push_sample(19 * PERIOD, (0.0, 0.0, 0.0))
    out += al.flush()
    assert [s.index for s in out] == list(range(20))
    _check_in_order(out)
    assert al.stats.duplicates == 3


def test_pending_table_stays_bounded_when_a_signal_never_arrives() -> None:
    al = StampAligner(period_ns=PERIOD)
    for k in range(5000):
        assert al.push("thrust", k * PERIOD, 0.0) == []
        assert al.push("position", k * PERIOD, 0.0) == []
    assert len(al._pending) <= 17
    assert al.stats.unaligned >= 2 * (5000 - 17)


def test_bad_inputs_raise_data_error() -> None:
    with pytest.raises(DataError):
        StampAligner().push("torque", 0, 1.0)
    with pytest.raises(DataError):
        StampAligner(signals=("a", "a"))
    with pytest.raises(DataError):
        StampAligner(period_ns=0)
    with pytest.raises(DataError):
        WindowScheduler(window=1)
    with pytest.raises(DataError):
        StampAligner().push_sample(0, (1.0,))


def _feed(sched: WindowScheduler, data: np.ndarray, indices) -> list[Window]:
    wins = []
    for k in indices:
        w = sched.push(Sample(int(k), int(k) * PERIOD, tuple(data[k])))
        if w is not None:
            wins.append(w)
    return wins


def test_windows_are_cut_on_the_index_grid_with_history() -> None:
    rng = np.random.default_rng(1)
    data = rng.standard_normal((3000, 3))
    sched = WindowScheduler(window=1000, hop=250, history=40)
    wins = _feed(sched, data, range(3000))
    # first window needs 1040 samples and must end on the grid: stop = 1250
    assert [w.stop_index for w in wins] == list(range(1250, 3001, 250))
    for w in wins:
        assert w.stop_index - w.start_index == 1000 and w.seq == w.stop_index // 250
        np.testing.assert_array_equal(w.values, data[w.start_index - 40:w.stop_index])
        np.testing.assert_array_equal(w.signal("speed"), data[w.start_index:w.stop_index, 1])
        assert w.start_stamp == w.start_index * PERIOD / 1e9
        assert w.end_stamp == (w.stop_index - 1) * PERIOD / 1e9
        rec = w.recording(500.0, with_history=False)
        np.testing.assert_array_equal(rec.thrust, data[w.start_index:w.stop_index, 0])
    assert sched.capacity == 1040


def test_a_gap_restarts_the_contiguous_count() -> None:
    data = np.zeros((4000, 3))
    indices = [k for k in range(4000) if k != 1500]
    wins = _feed(WindowScheduler(window=1000, hop=250), data, indices)
    for w in wins:
        assert not (w.start_index <= 1500 < w.stop_index)
    assert [w.stop_index for w in wins] == [1000, 1250, 1500, 2750, 3000, 3250, 3500, 3750, 4000]


def test_latest_queue_skips_the_oldest_and_counts() -> None:
    q: LatestQueue[int] = LatestQueue(maxsize=2)
    for i in range(5):
        q.put(i)
    assert q.skipped == 3 and len(q) == 2
    assert q.get(0.1) == 3 and q.get(0.1) == 4 and q.get(0.01) is None
    q.close()
    assert q.get(0.1) is None and q.closed


BUSY_S = 0.002


def test_slow_fits_skip_windows_but_never_lose_samples() -> None:
    """A producer at full speed and a worker 50x slower: every sample is stored, every
    window is either fitted or counted as skipped, memory stays fixed."""
    sched = WindowScheduler(window=200, hop=50)
    q: LatestQueue[Window] = LatestQueue(maxsize=1)
    fitted: list[int] = []
    errors: list[Exception] = []

    def fit(w: Window) -> float:
        c0 = time.thread_time()
        while time.thread_time() - c0 < BUSY_S:  # CPU the worker's clock must count
            pass
        time.sleep(0.01)  # and time it must not
        if w.seq == 30:
            raise DataError("bad window")
        return float(w.signal("thrust").sum())

    worker: FitWorker[Window, float] = FitWorker(
        q, fit, lambda w, r: fitted.append(w.seq), lambda w, e: errors.append(e),
        latency_of=lambda w: w.due_monotonic)
    worker.start()
    data = np.arange(60_000, dtype=float)[:, None].repeat(3, axis=1)
    for k in range(60_000):
        w = sched.push(Sample(k, k * PERIOD, tuple(data[k])))
        if w is not None:
            q.put(w)
        if k % 500 == 0:
            time.sleep(0.001)
    worker.stop()
    stats = worker.stats
    assert sched.samples == 60_000 and sched.capacity == 200
    assert stats.processed + q.skipped == sched.windows == (60_000 - 200) // 50 + 1
    assert q.skipped > 0 and stats.processed == len(fitted) + stats.failed
    assert stats.failed == len(errors) <= 1
    assert len(stats.latencies_s) == stats.processed
    # CPU seconds, not wall seconds: each fit burns BUSY_S of CPU, then sleeps 10 ms
    assert stats.processed * BUSY_S <= stats.cpu_s < stats.processed * (BUSY_S + 0.005)
    assert not worker.alive


def test_worker_runs_off_the_calling_thread() -> None:
    q: LatestQueue[int] = LatestQueue(maxsize=4)
    seen: list[str] = []
    worker: FitWorker[int, str] = FitWorker(
        q, lambda i: threading.current_thread().name, lambda i, r: seen.append(r))
    worker.start()
    q.put(1)
    deadline = time.monotonic() + 5
    while not seen and time.monotonic() < deadline:
        time.sleep(0.01)
    worker.stop()
    assert seen == ["fit-worker"]


class _Elsewhere:
    """A processor that computes in a thread of its own, one item after the other (as a
    worker process does); each item adds 1.0 to ``cpu`` (the CPU clock the worker reads).
    Item 1 is only computed once item 2 was handed over (a 60 s wait otherwise)."""

    def __init__(self) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self.pool = ThreadPoolExecutor(1)
        self.events: list[str] = []
        self.cpu = 0.0
        self.second = threading.Event()

    def __call__(self, item: int) -> int:
        self.events.append(f"call {item}")
        return self._work(item)

    def submit(self, item: int) -> Ticket:
        self.events.append(f"submit {item}")
        if item == 2:
            self.second.set()
        fut = self.pool.submit(self._work, item)
        return Ticket(fut, lambda: self._collect(item, fut))

    def _collect(self, item: int, fut: object) -> int:
        self.events.append(f"collect {item}")
        return fut.result()  # type: ignore[attr-defined,no-any-return]

    def _work(self, item: int) -> int:
        if item == 1:
            self.events.append("overlapped" if self.second.wait(60) else "not overlapped")
        self.cpu += 1.0
        if item == 3:
            raise DataError("bad item")
        return 10 * item


@pytest.mark.parametrize("ahead", [1, 2])
def test_items_handed_over_ahead_overlap_and_come_back_in_order(ahead: int) -> None:
    proc = _Elsewhere()
    q: LatestQueue[int] = LatestQueue(maxsize=8)
    got: list[int] = []
    errors: list[Exception] = []
    worker: FitWorker[int, int] = FitWorker(
        q, proc, lambda i, r: got.append(r), lambda i, e: errors.append(e),
        cpu_clock=lambda: proc.cpu, ahead=ahead)
    if ahead == 1:
        proc.second.set()  # one at a time: item 1 does not wait for item 2
    for item in range(1, 7):
        q.put(item)
    worker.start()
    worker.stop(timeout=120)  # the queue is closed: what was taken and queued is finished
    stats = worker.stats
    assert not worker.alive
    assert got == [10, 20, 40, 50, 60] and [str(e) for e in errors] == ["bad item"]
    assert stats.processed == 6 and stats.failed == 1 and q.skipped == 0
    assert stats.cpu_s == 6.0  # each item's CPU counted once, however they overlapped
    if ahead == 1:
        assert [e for e in proc.events if e.startswith("submit")] == []
    else:
        assert proc.events.index("submit 2") < proc.events.index("collect 1")
        assert "overlapped" in proc.events
        assert max(int(e.split()[1]) for e in proc.events[:proc.events.index("collect 1")]
                   if e.startswith("submit")) == 2  # never more than two handed over
    proc.pool.shutdown()
