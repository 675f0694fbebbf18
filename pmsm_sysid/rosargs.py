"""``--ros-args`` for the ROS verbs (run, monitor, record, replay), handed to rclpy.

Everything after ``--ros-args`` on the command line (up to a lone ``--``) is ROS's, as for
any ROS 2 executable: ``--params-file FILE``, ``-p name:=value``, ``-r from:=to``,
``--log-level``, ... rclpy parses it when the verb initialises its context, so it applies to
every node of the process, with the usual rules: a ``-p`` value applies to each node that has
that parameter; a params file's ``/**:`` section to all nodes and ``/ns/node:`` (or
``/**/node:``) to that node. One convenience: a params-file section keyed by a bare node name
(``pmsm_identifier:``, no leading slash) names that node *in the pipeline's namespace*, as if
written ``/pmsm/pmsm_identifier:`` (plain ROS would look for it in the root namespace, where
a pipeline never is, and silently ignore it). The verb's own options (``--hop``, ``--set``)
win over ``--ros-args``.
"""

from __future__ import annotations

import itertools
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from .core.errors import PmsmSysidError

ROS_ARGS = "--ros-args"
ROS_VERBS = ("run", "monitor", "record", "replay")
PARAMS_FILE_FLAGS = ("--params-file",)


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(the verb's own arguments, the ROS arguments from ``--ros-args`` on).

    A lone ``--`` ends the ROS arguments; what follows is the verb's again."""
    argv = list(argv)
    if ROS_ARGS not in argv:
        return argv, []
    i = argv.index(ROS_ARGS)
    rest = argv[i:]
    if "--" in rest:
        j = rest.index("--")
        return argv[:i] + rest[j + 1:], rest[:j]
    return argv[:i], rest


def params_files(ros_args: Sequence[str]) -> list[str]:
    """The files named by ``--params-file`` in ``ros_args``."""
    return [ros_args[i + 1] for i, a in enumerate(ros_args[:-1]) if a in PARAMS_FILE_FLAGS]


def _load(path: str) -> dict[str, Any]:
    import yaml

    p = Path(path)
    if not p.is_file():
        raise PmsmSysidError(f"--params-file {path}: no such file")
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise PmsmSysidError(f"--params-file {path}: not readable YAML ({first})") from exc
    if not isinstance(data, dict) or not data:
        raise PmsmSysidError(f"--params-file {path}: expected a ROS 2 parameters file "
                             "(node name: ros__parameters: name: value)")
    return data


def check_ros_args(ros_args: Sequence[str]) -> None:
    """Bad ``--ros-args`` found before any work: a flag without its value, a missing or
    unreadable params file. (rclpy checks the rest when the context is initialised.)"""
    if not ros_args:
        return
    if ros_args[-1] in (*PARAMS_FILE_FLAGS, "-p", "--param", "-r", "--remap"):
        raise PmsmSysidError(f"--ros-args: {ros_args[-1]} needs a value")
    for flag, value in itertools.pairwise(ros_args):
        if flag in ("-p", "--param", "-r", "--remap") and ":=" not in value:
            raise PmsmSysidError(f"--ros-args: {flag} takes name:=value, got '{value}'")
    for path in params_files(ros_args):
        _load(path)


def ros_namespace(ros_args: Sequence[str], namespace: str) -> str:
    """The namespace the nodes end up in: ``-r __ns:=/x`` wins over ``namespace``."""
    for i, a in enumerate(ros_args[:-1]):
        if a in ("-r", "--remap") and ros_args[i + 1].startswith("__ns:="):
            return ros_args[i + 1].split(":=", 1)[1]
    return namespace


def _rewrite(data: dict[str, Any], namespace: str) -> dict[str, Any] | None:
    """``data`` with bare node-name keys put in ``namespace``; None if there are none."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    bare = [k for k, v in data.items() if isinstance(k, str) and not k.startswith("/")
            and isinstance(v, dict) and "ros__parameters" in v]
    if not bare:
        return None
    return {(f"{ns}/{k}" if k in bare else k): v for k, v in data.items()}


@contextmanager
def prepared(ros_args: Sequence[str], namespace: str) -> Iterator[list[str]]:
    """``ros_args`` checked, with params files that key sections by a bare node name
    replaced by a temporary copy keyed ``<namespace>/<node>`` (see the module docstring).
    The copies' directory is made only when a file needs one: a process killed meanwhile
    cannot remove it, and a run without such a file leaves nothing behind."""
    import yaml

    check_ros_args(ros_args)
    out = list(ros_args)
    ns = ros_namespace(ros_args, namespace)
    with ExitStack() as stack:
        tmp: Path | None = None
        for i, a in enumerate(out[:-1]):
            if a not in PARAMS_FILE_FLAGS:
                continue
            moved = _rewrite(_load(out[i + 1]), ns)
            if moved is None:
                continue
            if tmp is None:
                tmp = Path(stack.enter_context(
                    tempfile.TemporaryDirectory(prefix="pmsm_sysid_params_")))
            copy = tmp / f"{i}_{Path(out[i + 1]).name}"
            copy.write_text(yaml.safe_dump(moved, sort_keys=False))
            out[i + 1] = str(copy)
        yield out
