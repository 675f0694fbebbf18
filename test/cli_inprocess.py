"""``pmsm-sysid ARGS`` of an offline verb in the test process: what the console script does
(``pmsm_sysid.cli.main``: its exit status, stdout and stderr), without starting a Python
and importing numpy, scipy and matplotlib again for every call (about 1.2 s of CPU each).

For the offline verbs (no ROS, no signals) and for fleets whose output is checked by its
result (their Dask workers are processes still); the console scripts themselves are run as
processes in test_install.py, and the ROS verbs, a fleet whose stderr must be empty (Dask's
logs reach a process's stream, not a captured one), and every signal or kill test stay
separate processes. The ROS verbs' refused input runs in-process through
reliability_helpers.ros_verb.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path

from pmsm_sysid.cli import main

OFFLINE = ("simulate", "identify", "gfrf", "diagnose", "fit-plant", "report", "import-mat",
           "fleet")


@contextmanager
def environment(env: Mapping[str, str] | None, cwd: Path | str | None) -> Iterator[None]:
    """``env`` as the whole environment and ``cwd`` as the working directory, for the
    call only (as ``subprocess.run(env=, cwd=)`` would give the process)."""
    saved, here = dict(os.environ), os.getcwd()
    try:
        if env is not None:
            os.environ.clear()
            os.environ.update(env)
        if cwd is not None:
            os.chdir(cwd)
        yield
    finally:
        os.chdir(here)
        os.environ.clear()
        os.environ.update(saved)


@contextmanager
def warnings_as_a_process() -> Iterator[None]:
    """Warnings filtered as a fresh interpreter filters them and printed on ``sys.stderr``
    (pytest otherwise records them out of sight, and each is shown once per place
    per test process, not per call): an extra line a process would print is seen."""
    def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: object = None, line: str | None = None) -> None:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    with warnings.catch_warnings():  # also forgets which warnings were shown before
        warnings.resetwarnings()
        warnings.simplefilter("default")
        for category in (ResourceWarning, ImportWarning, PendingDeprecationWarning,
                         DeprecationWarning):
            warnings.filterwarnings("ignore", category=category)
        warnings.filterwarnings("default", category=DeprecationWarning, module="__main__")
        warnings.showwarning = show
        yield


def exit_status(*args: str) -> int:
    """``pmsm_sysid.cli.main(ARGS)`` here: its exit status, argparse's usage errors and
    ``--help`` (a ``SystemExit``) included."""
    try:
        return main(list(args))
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)


def invoke(*args: str, env: Mapping[str, str] | None = None,
           cwd: Path | str | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``pmsm-sysid ARGS`` (an offline verb) here; the result as ``subprocess.run``
    gives it (``returncode``, ``stdout``, ``stderr``, warnings printed on it as a process
    prints them). An exception that escapes ``main`` (a traceback in a process) fails the
    calling test."""
    verb = next((a for a in args if not a.startswith("-")), "")
    assert verb in OFFLINE, f"{verb!r} is not an offline verb: run it as a process"
    out, err = io.StringIO(), io.StringIO()
    with environment(env, cwd), redirect_stdout(out), redirect_stderr(err), \
            warnings_as_a_process():
        code = exit_status(*args)
    return subprocess.CompletedProcess(["pmsm-sysid", *args], code, out.getvalue(),
                                       err.getvalue())
