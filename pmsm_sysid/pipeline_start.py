"""Starting a pipeline's simulator at the right moment (:func:`.app.build_pipeline`): the sim
node is held until its subscribers in other processes are matched (another process's
identifier, the recorder process), so nothing is published into the void while the
processes discover each other."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from .app import Pipeline


def wait_until_matched(sim: Any, executor: SingleThreadedExecutor, wait_s: float,
                       subscribers: int = 1) -> bool:
    """Hold the sim node until each of its input publishers is matched by ``subscribers``
    subscribers in other processes (or ``wait_s`` passes), then start it: nothing is
    published into the void while the processes discover each other (an identifier that
    records is two: the recorder is a process of its own)."""
    pubs = sim.input_publishers
    sim.stop_timer()
    try:
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and sim.context.ok():
            if all(p.get_subscription_count() >= subscribers for p in pubs):
                return True
            executor.spin_once(timeout_sec=0.1)
        return False
    finally:
        sim.start_timer()


def start_recorder(ctx: Context, path: str, namespace: str, identifier: Any = None) -> Any:
    """A recorder process (inputs and identification outputs) writing a new bag at
    ``path`` on the context's domain; the inputs are the topics the ``identifier`` here
    listens to (e.g. a robot's JointState topic), else the three under ``namespace``."""
    from .nodes.recorder_process import RecorderProcess

    inputs = identifier.input_topic_types if identifier is not None else None
    return RecorderProcess(path, namespace=namespace, domain_id=ctx.get_domain_id(),
                           inputs=inputs)


def wait_for_recorder(pipe: Pipeline, timeout_s: float) -> bool:
    """Hold the sim until the recorder process has matched every publisher of this
    process on a recorded topic (it then misses no sample), at most ``timeout_s``."""
    rec, sim = pipe.recorder, pipe.sim
    pubs = [p for n in pipe.nodes.values() for p in n.publishers if p.topic_name in rec.topics]
    local = {}
    for p in pubs:
        local[p.topic_name] = sum(s.topic_name == p.topic_name
                                  for n in pipe.nodes.values() for s in n.subscriptions)
    if sim is not None and not pipe.stepped:
        sim.stop_timer()
    try:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > local[p.topic_name] for p in pubs):
                return True
            time.sleep(0.02)
        return False
    finally:
        if sim is not None and not pipe.stepped:
            sim.start_timer()
