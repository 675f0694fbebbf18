"""Shared pieces of the reliability tests: the command line (in process), one-line error checks, and
bags written message by message (receive time and header stamp chosen independently, as a
real recorder sees them). :func:`ros_verb` runs a ROS verb in this process (for the CLI
tests of run, record, replay and monitor where the process is not what they check)."""

from __future__ import annotations

import json
import subprocess
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from cli_inprocess import environment, exit_status, invoke, warnings_as_a_process
from narx_systems import QUADRATIC, simulate, white_input
from rosbags.rosbag2 import Writer

from pmsm_sysid import topics as tp
from pmsm_sysid.bagio import connection_args, storage_plugin, typestore, write_recording
from pmsm_sysid.bagio.cdr import encode_stamped
from pmsm_sysid.cli import main
from pmsm_sysid.core.recording.signals import Recording

FS = 500.0
PERIOD_NS = 2_000_000
SIGNALS = ("thrust", "speed", "position")
SMALL = ["--ny", "2", "--nu", "2", "--terms", "5"]  # the known system's structure


def run_cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """``pmsm-sysid ARGS`` of an offline verb, in this process (:mod:`cli_inprocess`)."""
    return invoke(*args, env=env)


def ros_verb(capfd: Any, *args: str) -> subprocess.CompletedProcess[str]:
    """``pmsm-sysid ARGS`` of a ROS verb (run, record, replay, monitor) in this process: the
    exit status, and stdout and stderr as captured at the file descriptors (``capfd``), so
    that what rcl writes from C counts as a line too, as in a process. The environment is
    restored after the call, and warnings are printed on stderr as a process prints them.
    For input refused before any work, and for runs that end by themselves where the
    process is not what the test checks; what is signalled or killed, or checked as the
    user's process, runs as a process (one costs a Python, rclpy, numpy and scipy: about
    1.5 s of CPU, and a fork server of its own)."""
    capfd.readouterr()
    with environment(None, None), warnings_as_a_process():
        code = exit_status(*args)
    out, err = capfd.readouterr()
    return subprocess.CompletedProcess(["pmsm-sysid", *args], code, out, err)


def assert_one_line_error(proc: subprocess.CompletedProcess[str], *fragments: str) -> str:
    """Exit code 2, exactly one non-empty line on stderr naming the problem, no traceback."""
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    assert len(lines) == 1, proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def cli_error(capsys: Any, argv: list[str], *fragments: str) -> str:
    """As :func:`assert_one_line_error`, in this process (faster): ``main(argv)`` returns or
    exits with 2 and prints one line; a RuntimeWarning (overflow, invalid value: a separate
    process would print it as more lines) fails the test, any other exception propagates and
    fails it too."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1, (rc, err)
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def known_data(n: int = 5000, seed: int = 11) -> tuple[np.ndarray, np.ndarray]:
    """White input and the output of the known quadratic NARX system (narx_systems)."""
    u = white_input(n, seed=seed)
    return u, simulate(QUADRATIC, u, noise_std=1e-3, seed=seed)


def recording(u: np.ndarray, y: np.ndarray, t: np.ndarray | None = None,
              position: np.ndarray | None = None) -> Recording:
    """Thrust u, speed y, position = running sum of y (unless given), at 500 Hz."""
    t = np.arange(len(u)) / FS if t is None else np.asarray(t, dtype=np.float64)
    pos = np.cumsum(y) / FS if position is None else position
    return Recording(t=t, thrust=np.asarray(u, dtype=np.float64),
                     speed=np.asarray(y, dtype=np.float64),
                     position=np.asarray(pos, dtype=np.float64), sample_rate_hz=FS,
                     source="test")


def bag_of(path: Path, u: np.ndarray, y: np.ndarray, t: np.ndarray | None = None,
           position: np.ndarray | None = None) -> Path:
    write_recording(path, recording(u, y, t, position))
    return path


Message = tuple[str, int, bytes]  # topic, receive time (ns), CDR bytes


def input_messages(rec: Recording, stamps_ns: dict[str, np.ndarray] | None = None,
                   receive_ns: np.ndarray | None = None) -> list[tuple[str, int, int, float]]:
    """(signal, receive ns, stamp ns, value) of every sample; stamps per signal may differ."""
    nominal = np.round(rec.t * 1e9).astype(np.int64)
    recv = nominal if receive_ns is None else receive_ns
    out = []
    for k in range(len(rec)):
        for s in SIGNALS:
            stamp = nominal[k] if stamps_ns is None else stamps_ns[s][k]
            out.append((s, int(recv[k]), int(stamp), float(rec.signal(s)[k])))
    return out


def write_messages(path: Path, items: Iterable[tuple[str, int, int, float]],
                   extra: Iterable[tuple[str, str, int, bytes]] = (),
                   storage: str = "mcap", namespace: str = "/pmsm") -> Path:
    """A bag holding the input messages in the given receive order (plus ``extra`` raw
    messages: topic, type, receive ns, bytes), definitions embedded as the project does."""
    extra = list(extra)
    with Writer(path, version=9, storage_plugin=storage_plugin(storage)) as writer:
        conns: dict[str, Any] = {}

        def conn(topic: str, msgtype: str) -> Any:
            if topic not in conns:
                msgdef, digest = connection_args(msgtype)
                conns[topic] = writer.add_connection(topic, msgtype, msgdef=msgdef, rihs01=digest)
            return conns[topic]

        for signal, recv, stamp, value in items:
            msgtype = tp.INPUT_TYPES[signal]
            writer.write(conn(tp.input_topic(namespace, signal), msgtype), recv,
                         encode_stamped(msgtype, stamp, "pmsm", value))
        for topic, msgtype, recv, data in extra:
            writer.write(conn(topic, msgtype), recv, data)
    return path


def string_msg(text: str) -> bytes:
    store = typestore()
    return bytes(store.serialize_cdr(store.types["std_msgs/msg/String"](data=text),
                                     "std_msgs/msg/String"))


def identify_json(bag: Path, tmp: Path, *args: str,
                  capsys: Any = None) -> tuple[dict[str, Any], str]:
    """``identify`` in this process (fast); the JSON and what it printed."""
    out = tmp / f"model_{len(list(tmp.glob('model_*.json')))}.json"
    rc = main(["identify", str(bag), *SMALL, *args, "--json", str(out)])
    printed = capsys.readouterr().out if capsys is not None else ""
    assert rc == 0, printed
    return json.loads(out.read_text()), printed


def estimates(d: dict[str, Any]) -> dict[str, float]:
    return {t["name"]: float(t["estimate"]) for t in d["terms"]}
