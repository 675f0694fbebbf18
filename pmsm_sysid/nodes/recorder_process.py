"""The recorder of ``run --record`` in a process of its own (rclpy context, executor, GIL).

:class:`RecorderProcess` starts a :class:`~.recorder.RecorderNode` writing a new bag in a
worker process (``forkserver``: never a fork of a process that runs rclpy) and returns once
its subscriptions exist (a bag that cannot be created is refused there, one clear error). No
fit, analysis or publishing callback of the caller can delay it: it only competes for a core.

- Inputs: the three topics under the namespace, or ``inputs`` (topic -> type), e.g. the
  ``JointState`` topic an identifier takes its samples from.
- Progress: the messages recorded per input topic are in shared memory
  (:attr:`RecorderProcess.samples_recorded`), so a simulated motor can pace itself to the
  recorder as well as to the identifier.
- :meth:`RecorderProcess.stop`: the recorder takes every message still waiting (the caller
  has made sure its publishers were acknowledged), finalises the bag and returns its counts
  (messages per topic, stamp gaps and samples missing per input topic).
- The recorder ignores SIGINT/SIGTERM (the caller decides when it stops). If the caller dies
  (even SIGKILL), the recorder sees its control pipe close, takes what is waiting and
  finalises the bag: it stays readable, as it is, up to the moment of the kill. If the
  recorder itself is killed, the bag is flushed every ``flush_period_s`` (0.5 s): readable
  as it is, missing at most that much.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import PmsmSysidError
from ..core.online.workerproc import START_METHOD, start_server
from ..dds import use_packaged_profile
from ..topics import INPUT_TYPES, input_topic

NODE_NAME = "pmsm_record"
QUIET_ROUNDS = 3  # executor rounds without a new message: everything acknowledged is taken


def _drain(executor: Any, node: Any, timeout_s: float = 0.1) -> None:
    """Spin until QUIET_ROUNDS rounds in a row bring no message (bounded: 30 s)."""
    import time

    quiet, deadline = 0, time.monotonic() + 30.0
    while quiet < QUIET_ROUNDS and time.monotonic() < deadline:
        before = node.total
        executor.spin_once(timeout_sec=timeout_s)
        quiet = quiet + 1 if node.total == before else 0


def _tell(conn: Any, message: tuple[str, Any]) -> bool:
    """Send ``message`` to the caller; False when it is gone (its end of the pipe closed)."""
    try:
        conn.send(message)
    except (BrokenPipeError, ConnectionResetError):
        return False
    return True


def _serve(conn: Any, path: str, namespace: str, domain_id: int | None,
           topics: Sequence[str] | None, flush_s: float, progress: Any,
           inputs: dict[str, str] | None = None) -> None:
    """The recorder process: record until told to stop or the caller is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from ..bagio import BagRecorder
    from .recorder import RecorderNode

    use_packaged_profile()
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    try:
        try:
            bag = BagRecorder(path, flush_interval_s=flush_s)
        except PmsmSysidError as exc:
            _tell(conn, ("error", str(exc)))
            return
        node = RecorderNode(bag, context=ctx, namespace=namespace, topics=topics,
                            flush_period_s=flush_s, node_name=NODE_NAME, inputs=inputs)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        followed = input_topics(namespace, inputs)
        # the caller may be gone already (interrupted while this started): record nothing
        ready = _tell(conn, ("ready", None))
        command = _record(conn, executor, node, followed, progress) if ready else None
        _drain(executor, node)
        bag.close()
        for i, topic in enumerate(followed):
            progress[i] = node.counts[topic]
        if command is not None:
            _tell(conn, ("done", node.summary()))
        executor.shutdown(timeout_sec=2.0)
        node.destroy_node()  # type: ignore[no-untyped-call]
    finally:
        from rclpy.utilities import try_shutdown

        try_shutdown(context=ctx)


def input_topics(namespace: str, inputs: Mapping[str, str] | None) -> list[str]:
    """The input topics whose progress is followed: ``inputs`` or the three under
    ``namespace``."""
    return list(inputs) if inputs is not None else [input_topic(namespace, s)
                                                    for s in INPUT_TYPES]


def _record(conn: Any, executor: Any, node: Any, inputs: list[str], progress: Any) -> Any:
    """Spin until a command arrives (returned) or the caller's end of the pipe closes (None)."""
    while True:
        executor.spin_once(timeout_sec=0.05)
        for i, topic in enumerate(inputs):
            progress[i] = node.counts[topic]
        if conn.poll():
            try:
                return conn.recv()
            except EOFError:
                return None


class RecorderProcess:
    """A RecorderNode writing ``path`` in a process of its own (see the module docstring)."""

    def __init__(self, path: str | Path, *, namespace: str, domain_id: int | None,
                 topics: Sequence[str] | None = None, flush_period_s: float = 0.5,
                 ready_timeout_s: float = 120.0, inputs: Mapping[str, str] | None = None,
                 ) -> None:
        start_server()  # returns at once if it runs (else: started deaf to Ctrl-C)
        ctx: Any = multiprocessing.get_context(START_METHOD)
        self.path = Path(path)
        self.node_name = NODE_NAME
        from .recorder import default_topics

        inputs = None if inputs is None else dict(inputs)
        self.topics = set(default_topics(namespace, inputs)) if topics is None else set(topics)
        self.inputs = input_topics(namespace, inputs)
        self._conn, child = ctx.Pipe()
        self._progress = ctx.Array("q", len(self.inputs), lock=False)
        self._proc = ctx.Process(
            target=_serve, name="pmsm-recorder", daemon=False,
            args=(child, str(path), namespace, domain_id, topics, flush_period_s,
                  self._progress, inputs))
        self._proc.start()
        child.close()
        self.result: dict[str, Any] | None = None
        kind, text = self._receive(ready_timeout_s, "start")
        if kind != "ready":
            self._proc.join(10.0)
            raise PmsmSysidError(text)

    def _receive(self, timeout_s: float, what: str) -> tuple[str, Any]:
        if not self._conn.poll(timeout_s):
            self._end()
            raise PmsmSysidError(f"the recorder process did not {what} within {timeout_s:g} s")
        try:
            return self._conn.recv()  # type: ignore[no-any-return]
        except EOFError as exc:
            self._end()
            raise PmsmSysidError(f"the recorder process ended (exit code "
                                 f"{self._proc.exitcode}) before it could {what}") from exc

    @property
    def samples_recorded(self) -> int:
        """Samples recorded so far: the fewest messages over the input topics."""
        return int(min(self._progress))

    def samples_recorded_of(self, topics: Collection[str]) -> int:
        """Samples recorded so far of the input topics among ``topics`` (e.g. those that
        arrived: a speed derived from position never comes, and is no part of a sample):
        the fewest messages over them; over every input topic when none is among them."""
        counts = [n for t, n in zip(self.inputs, self._progress, strict=True) if t in topics]
        return int(min(counts)) if counts else self.samples_recorded

    @property
    def alive(self) -> bool:
        return bool(self._proc.is_alive())

    def stop(self, timeout_s: float = 60.0) -> dict[str, Any]:
        """Take what waits, finalise the bag, end the process; the recorder's summary."""
        if self.result is not None:
            return self.result
        try:
            self._conn.send(("stop", None))
        except OSError as exc:
            self._end()
            raise PmsmSysidError(f"the recorder process ended early (exit code "
                                 f"{self._proc.exitcode})") from exc
        _, summary = self._receive(timeout_s, "finalise the bag")
        self._proc.join(timeout_s)
        self._conn.close()
        self.result = dict(summary)
        return self.result

    def close(self) -> None:
        """Stop if still recording (errors ignored: used on the way out); idempotent."""
        if self.result is None and self._proc.is_alive():
            with contextlib.suppress(PmsmSysidError):
                self.stop()
        self._end()

    def _end(self) -> None:
        if self._proc.is_alive():
            self._proc.join(5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(5.0)
