"""``pmsm-sysid fleet`` on Dask: bad arguments stop before any work (one line, exit 2); bad
recordings are rows with their reason while the batch goes on (exit 1, the last line says
how many); a batch killed half way and resumed ends with every row once, the finished ones
not analysed again; the same command on a real Dask cluster (a scheduler and a worker
started as their own processes)."""

from __future__ import annotations

import inspect
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest
from cli_inprocess import invoke
from fleet_helpers import EXE, NOMINAL, drive, recording
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

import pmsm_sysid as ps
from pmsm_sysid.api.fleet_row import recording_row

JAZZY = get_typestore(Stores.ROS2_JAZZY)
DEADLINE_S = 900.0  # generous: only to end a hung test, never a performance check


def _fleet(*args: str, timeout: float = DEADLINE_S,
           bar: bool = False) -> subprocess.CompletedProcess[str]:
    """``pmsm-sysid fleet ARGS``; ``bar``: draw the progress bar though not on a terminal."""
    env = dict(os.environ, PMSM_SYSID_PROGRESS="1" if bar else "0")
    return subprocess.run([str(EXE), "fleet", *args], capture_output=True, text=True,
                          timeout=timeout, check=False, env=env)


def _in_process(*args: str, bar: bool = False) -> subprocess.CompletedProcess[str]:
    """``pmsm-sysid fleet ARGS`` run in this process: its exit status, stdout and stderr as
    the console script gives them, without an interpreter started for it (its local
    cluster's workers are processes of their own all the same). The executable's own exit
    status and stderr line are checked on a scheduler that does not answer, and a batch
    killed half way and its resumed run are processes of their own."""
    return invoke("fleet", *args,
                  env=dict(os.environ, PMSM_SYSID_PROGRESS="1" if bar else "0"))


def _one_line(proc: subprocess.CompletedProcess[str], *fragments: str) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ----------------------------------------------------------------------- bad arguments


def test_no_recordings_is_one_line_before_any_work(tmp_path: Path) -> None:
    proc = _in_process("--plant", str(NOMINAL), "--out", str(tmp_path / "out"))
    _one_line(proc, "pmsm-sysid fleet: error:", "no recordings given")
    proc = _in_process(str(tmp_path / "nowhere"), "--plant", str(NOMINAL), "--out",
                       str(tmp_path / "out"))
    _one_line(proc, "nowhere: no such file or directory")
    assert not (tmp_path / "out").exists()


def test_an_output_directory_holding_other_things_is_refused(tmp_path: Path) -> None:
    bag = ps.write_bag(ps.simulate(duration=0.2), tmp_path / "bag")
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    for extra in ([], ["--force"], ["--resume"]):
        proc = _in_process(str(bag), "--plant", str(NOMINAL), "--out", str(out), *extra)
        _one_line(proc, f"--out {out}: holds other things (thesis.tex)")
    assert sorted(p.name for p in out.iterdir()) == ["thesis.tex"]


def test_a_scheduler_that_does_not_answer_is_one_line_before_any_work(tmp_path: Path) -> None:
    bag = ps.write_bag(ps.simulate(duration=0.2), tmp_path / "bag")
    address = f"tcp://127.0.0.1:{_free_port()}"
    started = time.monotonic()
    proc = _fleet(str(bag), "--plant", str(NOMINAL), "--out", str(tmp_path / "out"),
                  "--scheduler", address, "--connect-timeout", "0.5")
    _one_line(proc, f"--scheduler {address}: no Dask scheduler answers there within 0.5 s")
    assert time.monotonic() - started < 120  # the connect timeout, not a hang
    assert not (tmp_path / "out").exists()
    proc = _in_process(str(bag), "--plant", str(NOMINAL), "--out", str(tmp_path / "out"),
                       "--scheduler", "tcp://127.0.0.1:notaport")
    _one_line(proc, "--scheduler tcp://127.0.0.1:notaport: not a scheduler address")
    # without --connect-timeout a scheduler has 5 s to answer, from Python too
    from pmsm_sysid.cli import build_parser

    args = build_parser().parse_args(["fleet", str(bag), "--plant", str(NOMINAL), "--out",
                                      str(tmp_path / "out"), "--scheduler", address])
    assert args.connect_timeout == 5.0
    assert inspect.signature(ps.fleet).parameters["connect_timeout"].default == 5.0


def test_without_the_fleet_extra_the_verb_names_it(tmp_path: Path) -> None:
    bag = ps.write_bag(ps.simulate(duration=0.2), tmp_path / "bag")
    code = ("import sys\n"
            "for name in ('dask', 'distributed', 'pyarrow'):\n"
            "    sys.modules[name] = None  # as after a plain 'pip install'\n"
            "from pmsm_sysid.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    proc = subprocess.run([sys.executable, "-c", code, "fleet", str(bag), "--plant",
                           str(NOMINAL), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300, check=False)
    _one_line(proc, "fleet needs dask[distributed] and pyarrow",
              "pip install '.[fleet]' (in the pmsm_sysid source directory)")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("kwargs", "fragment"), [
    ({"client": "tcp://127.0.0.1:8786"}, "client must be a dask.distributed.Client"),
    ({"resume": True}, "resume needs out"), ({"workers": 0}, "workers must be at least 1"),
    ({"baseline": 2}, "baseline must be at least 3"), ({"min_change": 1.5}, "min_change"),
    ({"axis_from": "name"}, "axis_from must be one of"), ({"alpha": 2.0}, "alpha"),
    ({"connect_timeout": 0}, "connect_timeout must be a positive"),
    ({"plant": "no/such.yaml"}, "no such plant file")])
def test_bad_api_options_raise_before_any_work(tmp_path: Path, kwargs: dict[str, object],
                                               fragment: str) -> None:
    with pytest.raises(ps.PmsmSysidError) as info:
        ps.fleet(str(tmp_path / "nothing"), **{"plant": NOMINAL, **kwargs})  # type: ignore
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_the_progress_bar_counts_done_and_failed_with_the_rate(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from pmsm_sysid.api.fleet_batch import FleetProgress
    from pmsm_sysid.cli.fleet import _Bars

    monkeypatch.setenv("PMSM_SYSID_PROGRESS", "1")
    bars = _Bars()
    bars(FleetProgress(2, stage="reading recordings"))
    bars(FleetProgress(2, done=2, stage="reading recordings"))
    for done, failed in ((0, 0), (1, 0), (2, 1), (3, 1)):
        bars(FleetProgress(3, done=done, failed=failed, skipped=4))
    bars.close()
    err = capsys.readouterr().err
    assert "reading recordings" in err and "2/2" in err
    assert "fleet" in err and "3/3" in err and "failed 1" in err and "/min" in err


# ----------------------------------------------------------------------- bad recordings


def _empty_bag(path: Path) -> Path:
    """The three topics, no message."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for name, msgtype in (("thrust", "geometry_msgs/msg/WrenchStamped"),
                              ("speed", "geometry_msgs/msg/TwistStamped"),
                              ("position", "geometry_msgs/msg/PointStamped")):
            w.add_connection(f"/pmsm/{name}", msgtype, typestore=JAZZY)
    return path


def _unreadable_bag(path: Path) -> Path:
    path.mkdir()
    (path / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: [\n")
    (path / f"{path.name}_0.mcap").write_bytes(b"\x89MCAP0\r\nnot really")
    return path


@pytest.mark.slow
def test_bad_recordings_are_rows_with_their_reason_and_the_batch_goes_on(
        tmp_path: Path) -> None:
    good = recording(tmp_path / "good", drive(), seed=1, day=0)
    short = recording(tmp_path / "short", drive(), seed=2, day=1, duration=2.0)
    empty = _empty_bag(tmp_path / "empty")
    broken = _unreadable_bag(tmp_path / "broken")
    out = tmp_path / "out"
    proc = _in_process(str(good), str(short), str(empty), str(broken), "--plant",
                       str(NOMINAL), "--out", str(out), "--workers", "2", "--json",
                       str(tmp_path / "s.json"), bar=True)
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    assert "4/4" in proc.stderr and "failed 3" in proc.stderr and "/min" in proc.stderr
    last = proc.stdout.strip().splitlines()[-1]
    assert last.startswith("fleet: 4 recording axes analysed, 3 failed"), last
    rows = {r["recording"]: r for r in pq.read_table(out / "results.parquet").to_pylist()}
    assert rows[str(good)]["status"] == "ok" and rows[str(good)]["error"] is None
    assert rows[str(good)]["mass_kg"] is not None
    reasons = {k: r["error"] for k, r in rows.items() if r["status"] == "error"}
    assert "too short: 2 s of data" in reasons[str(short)]
    assert "empty recording" in reasons[str(empty)]
    assert reasons[str(broken)].startswith(str(broken) + ":")
    assert all("\n" not in r and "Traceback" not in r for r in reasons.values())
    assert rows[str(short)]["duration_s"] == pytest.approx(2.0)
    assert rows[str(short)]["start_time"] is not None
    assert json.loads((tmp_path / "s.json").read_text())["failed"] == 3


# ----------------------------------------------------------------------- kill and resume


@pytest.fixture(scope="module")
def five_recordings(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    root = tmp_path_factory.mktemp("five")
    return [recording(root / f"day{i}", drive(), seed=10 + i, day=i, duration=6.0)
            for i in range(5)]


def _parts(out: Path) -> list[Path]:
    return sorted((out / "parts").glob("*.parquet")) if (out / "parts").is_dir() else []


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_a_batch_killed_half_way_resumes_without_losing_or_repeating_a_row(
        tmp_path: Path, five_recordings: list[Path]) -> None:
    out = tmp_path / "out"
    args = [*map(str, five_recordings), "--plant", str(NOMINAL), "--out", str(out),
            "--workers", "1"]
    proc = subprocess.Popen([str(EXE), "fleet", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + DEADLINE_S
        while len(_parts(out)) < 2 and proc.poll() is None:  # two rows finished
            assert time.monotonic() < deadline
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI and the workers it started
    finally:
        proc.wait(timeout=60)
    done = {r["content_sha256"]: r for p in _parts(out)
            for r in pq.read_table(p).to_pylist()}
    assert 2 <= len(done) < 5
    if (out / "results.parquet").exists():  # whatever was last written is a whole table
        assert pq.read_table(out / "results.parquet").num_rows <= len(done)
    again = _fleet(*args, "--resume", "--quiet", bar=True)
    assert again.returncode == 0, again.stderr[-3000:]
    assert again.stderr == ""  # --quiet: no bar even where one is asked for
    last = again.stdout.strip().splitlines()[-1]
    assert f"{5 - len(done)} recording axes analysed, 0 failed, {len(done)} done before" \
        in last, last
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert len(table) == 5 and len({r["content_sha256"] for r in table}) == 5
    assert sorted(r["recording"] for r in table) == sorted(map(str, five_recordings))
    for r in table:  # the rows finished before the kill were not analysed again
        if r["content_sha256"] in done:
            assert r["analysed_at"] == done[r["content_sha256"]]["analysed_at"]
    assert not (out / "parts").exists() and (out / "index.html").is_file()
    # copied under other names and run again: nothing to do, by content
    moved = tmp_path / "moved"
    moved.mkdir()
    for i, p in enumerate(five_recordings[:2]):
        shutil.copytree(p, moved / f"copy{i}")
    third = _in_process(str(moved), *args[5:], "--resume")  # nothing to analyse: no cluster
    assert third.returncode == 0 and "0 recording axes analysed" in third.stdout, third.stdout


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_ctrl_c_while_the_local_cluster_starts_is_one_line(
        tmp_path: Path, five_recordings: list[Path]) -> None:
    """A terminal's Ctrl-C (SIGINT to every process of the group: the CLI, its fork server
    and the workers) as soon as the CLI has started another process: the one line saying
    what was kept, exit 130, no traceback from any process, nothing left running."""
    out = tmp_path / "out"
    proc = subprocess.Popen([str(EXE), "fleet", *map(str, five_recordings[:2]), "--plant",
                             str(NOMINAL), "--out", str(out), "--workers", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=dict(os.environ,
                                                             PMSM_SYSID_PROGRESS="0"))
    try:
        deadline = time.monotonic() + DEADLINE_S
        while not _others_in_group(proc.pid) and proc.poll() is None:  # workers starting
            assert time.monotonic() < deadline
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=DEADLINE_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, (stdout, stderr)
    lines = [ln for ln in (stdout + stderr).splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fleet: interrupted after "), lines
    deadline = time.monotonic() + 60.0  # the fork server ends once it sees the CLI gone
    while _others_in_group(proc.pid):  # the CLI itself is reaped
        assert time.monotonic() < deadline, "a process of the fleet outlived it"
        time.sleep(0.05)


def _others_in_group(pgid: int) -> list[int]:
    """The processes of process group ``pgid`` other than its leader (Linux /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue  # ended meanwhile
        if int(fields[2]) == pgid and int(stat.parent.name) != pgid:
            found.append(int(stat.parent.name))
    return found


# ----------------------------------------------------------------------- --sim


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_a_recording_of_the_simulator_is_the_reference_with_sim(
        tmp_path: Path, five_recordings: list[Path]) -> None:
    """The simulator leaves the rail's friction out: each row holds the real axis's fitted
    plant (5 N of Coulomb friction) and names the friction as what the simulation lacks."""
    sim = recording(tmp_path / "sim", drive(coulomb_friction=None), seed=99, day=0)
    out = tmp_path / "out"
    args = [*map(str, five_recordings[:2]), "--out", str(out), "--workers", "1"]
    proc = _in_process(*args, "--sim", str(sim))
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["ok", "ok"], [r["error"] for r in rows]
    for r in rows:
        assert r["coulomb_friction.amplitude_n"] == pytest.approx(5.0, rel=0.05)
        assert r["coulomb_friction.amplitude_n.std"] > 0 and r["mass_kg.std"] > 0
        assert "coulomb_friction" in r["effects"] and "coulomb_friction" in r["diagnosed"]
        assert r["nrmse_after"] < r["nrmse_before"]
    manifest = json.loads((out / "fleet.json").read_text())
    assert set(manifest["reference"]) == {"sim_sha256", "sim_namespace"}
    # the rows were made against the simulation: resuming against a plant file is refused
    _one_line(_in_process(*args, "--plant", str(NOMINAL), "--resume"), "another reference")
    # a simulator's recording that cannot be read is refused before any work
    _one_line(_in_process(*args[:2], "--out", str(tmp_path / "new"), "--sim",
                          str(tmp_path / "nosim")), "nosim")
    assert not (tmp_path / "new").exists()


@pytest.mark.slow
def test_a_simulation_fitted_once_gives_the_same_diagnosis() -> None:
    """The row reuses the simulator's fitted plant (once per worker): the comparison is the
    one ``diagnose --sim`` makes fitting it each time."""
    from pmsm_sysid.api.fleet_row import _sim_fit
    from pmsm_sysid.core.discrepancy import DiagnoseOptions
    from pmsm_sysid.core.discrepancy.against import diagnose_sim

    repo = NOMINAL.parents[1]
    sim, real = repo / "bags" / "paper_speed_nominal", repo / "bags" / "paper_speed_coulomb"
    each_time = ps.diagnose(None, real, sim=sim, replay=False, gfrf=False).to_dict()
    opts = DiagnoseOptions(replay=False, gfrf=False)
    sim_rec, fitted = _sim_fit(str(sim), None, opts, "x")
    assert _sim_fit(str(sim), None, opts, "x")[1] is fitted  # once per process
    once = diagnose_sim(sim_rec, ps.read_bag(real), None, opts, sim_fit=fitted).to_dict()
    for key in ("changes", "effects", "fit", "real_plant", "sim_plant", "corrected_plant"):
        assert once[key] == each_time[key], key
    assert [c["parameter"] for c in once["changes"]] == ["coulomb_friction.amplitude_n"]


# ----------------------------------------------------------------------- a real cluster


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[str]:
    """A Dask scheduler and one worker, each its own process on this host, with the
    worker settings of the fleet's local cluster (as docs/fleet.md says: a Dask
    configuration file, in the directory DASK_CONFIG names)."""
    import yaml

    from pmsm_sysid.batch.cluster import WORKER_CONFIG

    info = tmp_path / "scheduler.json"
    (tmp_path / "dask").mkdir()
    settings: dict[str, Any] = {}
    for key, value in WORKER_CONFIG.items():
        *parents, name = key.split(".")
        inner = settings
        for p in parents:
            inner = inner.setdefault(p, {})
        inner[name] = value
    (tmp_path / "dask" / "pmsm-sysid.yaml").write_text(yaml.safe_dump(settings))
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               DASK_CONFIG=str(tmp_path / "dask"))
    quiet = {"env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    # both started at once: the worker reads the scheduler's address from its file
    scheduler = subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host",
                                  "127.0.0.1", "--port", "0", "--no-dashboard",
                                  "--scheduler-file", str(info)], **quiet)
    worker = subprocess.Popen([sys.executable, "-m", "dask", "worker", "--scheduler-file",
                               str(info), "--nthreads", "1", "--nworkers", "1",
                               "--no-dashboard", "--host", "127.0.0.1",
                               "--name", "fleet-test-worker"], **quiet)
    try:
        deadline = time.monotonic() + 120
        while not (info.is_file() and info.stat().st_size):
            assert time.monotonic() < deadline and scheduler.poll() is None
            time.sleep(0.05)
        yield json.loads(info.read_text())["address"]
    finally:
        # the worker first, while its scheduler still answers its goodbye (a worker whose
        # scheduler is gone waits out its reconnection before it exits)
        for p in (worker, scheduler):
            p.terminate()
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_the_same_command_runs_on_a_dask_cluster(tmp_path: Path, dask_cluster: str,
                                                 five_recordings: list[Path]) -> None:
    from dask.distributed import Client

    out = tmp_path / "out"
    proc = _in_process(*map(str, five_recordings[:2]), "--plant", str(NOMINAL), "--out",
                       str(out), "--scheduler", dask_cluster)
    assert proc.returncode == 0, proc.stderr[-3000:]
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["status"] for r in table] == ["ok", "ok"]
    with Client(dask_cluster, timeout=30) as client:
        ran = client.run_on_scheduler(lambda dask_scheduler: {
            name: dict(p.state_counts) for name, p in dask_scheduler.task_prefixes.items()})
        workers = client.scheduler_info()["workers"]
    # the rows were the cluster's tasks, each run to its result (counts of state entries)
    assert ran["recording_row"]["memory"] == 2, ran
    assert [w["name"] for w in workers.values()] == ["fleet-test-worker"]


# ----------------------------------------------------------------------- long recordings


@pytest.mark.slow
def test_a_long_recording_is_used_in_the_spans_fit_plant_and_diagnose_use(
        tmp_path: Path) -> None:
    """A recording longer than max_samples: the row holds the numbers of ``fit_plant`` and
    ``diagnose`` with the same budget (the same ten spans, read once), the whole recording's
    duration and the samples used."""
    bag = recording(tmp_path / "long", drive(), seed=5, day=0, duration=60.0)
    row = recording_row(bag, ps.Plant.from_yaml(NOMINAL), max_samples=20_000)
    assert row["status"] == "ok", row["error"]
    assert row["samples"] == 20_000 and row["duration_s"] == pytest.approx(60.0, abs=0.01)
    fit = ps.fit_plant(bag, max_samples=20_000)
    assert fit.excerpt is not None and fit.excerpt.used == 20_000
    assert row["mass_kg"] == fit.plant.mass_kg
    assert row["mass_kg.std"] == fit.std["mass_kg"]
    assert row["coulomb_friction.amplitude_n"] == fit.plant.coulomb_friction.amplitude_n
    found = ps.diagnose(NOMINAL, bag, replay=False, gfrf=False, max_samples=20_000).to_dict()
    assert row["nrmse_before"] == found["fit"]["validation"]["nrmse_before"]
    assert row["nrmse_after"] == found["fit"]["validation"]["nrmse_after"]
    assert row["diagnosed"] == [e["name"] for e in found["effects"]] == ["coulomb_friction"]


#: In a process of its own (a fork server runs once per process, with the imports of
#: whoever started it): a local cluster of one worker, its settings, the numerical modules
#: loaded in it before and after a row against a plant and one against a simulator's
#: recording, as JSON.
CLUSTER_SCRIPT = """
import json, os, sys
import dask
import pmsm_sysid as ps
from pmsm_sysid.api.fleet_row import recording_row
from pmsm_sysid.batch.cluster import local_cluster

def settings():
    return (dask.config.get("distributed.worker.profile.enabled"),
            os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("OPENBLAS_NUM_THREADS"))

def modules():
    return os.getppid(), sorted(m for m in sys.modules
                                if m.split(".")[0] in ("pmsm_sysid", "numpy", "scipy"))

def defaults():
    import dask.distributed  # loads Dask distributed's settings
    return [dask.config.get(key) for key in (
        "distributed.worker.profile.enabled",
        "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_",
        "distributed.worker.multiprocessing-method")]

real, sim, plant = sys.argv[1:4]
dask_before = defaults()
with local_cluster(1) as client:
    (got,) = client.run(settings).values()
    (parent, before), = client.run(modules).values()
    rows = client.gather([client.submit(recording_row, real, ps.Plant.from_yaml(plant)),
                          client.submit(recording_row, real, sim=sim)])
    (_, after), = client.run(modules).values()
print(json.dumps({"settings": got, "parent": parent, "me": os.getpid(), "before": before,
                  "after": after, "rows": [[r["status"], r["error"]] for r in rows],
                  "dask": [dask_before, defaults()]}))
"""


def test_the_local_clusters_workers_run_without_the_profiler_and_the_trim_threshold(
        tmp_path: Path) -> None:
    """Dask's profiler samples every thread's stack each 10 ms, and the glibc trim threshold
    Dask's nannies set maps every array over 128 kB anew; the fleet's local workers have
    neither (they cost about a fifth of a worker's CPU time each on fleet rows), and keep
    one BLAS thread. They are forked from a fork server (not children of the caller) that
    imported what a row needs: a row against a plant or a simulator's recording then
    imports no numerical module of its own. Dask's own settings are left as they were."""
    from pmsm_sysid.api.fleet_row import ROW_MODULES

    real, sim = (recording(tmp_path / name, drive(), seed=seed, day=0)
                 for name, seed in (("real", 11), ("sim", 12)))
    proc = subprocess.run([sys.executable, "-c", CLUSTER_SCRIPT, str(real), str(sim),
                           str(NOMINAL)], capture_output=True, text=True, timeout=DEADLINE_S,
                          env=dict(os.environ, OPENBLAS_NUM_THREADS="1"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.splitlines()[-1])
    assert got["settings"] == [False, None, "1"]
    assert got["parent"] != got["me"]
    assert set(ROW_MODULES) <= set(got["before"])
    assert got["rows"] == [["ok", None], ["ok", None]]
    assert sorted(set(got["after"]) - set(got["before"])) == []
    assert got["dask"] == [[True, 65536, "spawn"]] * 2  # Dask's defaults, as they were


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_a_local_cluster_starts_no_more_workers_than_recordings_to_analyse(
        five_recordings: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker started for nothing costs its start: one recording to analyse starts no
    cluster (it is analysed in the calling process), two left (of three, one already in the
    table) on one worker start one, two left (of five) on ``--workers 4`` start two."""
    import pmsm_sysid.batch.cluster as cluster

    asked: list[int] = []
    real = cluster.local_cluster

    def counted(workers: int) -> Any:
        asked.append(workers)
        return real(workers)

    monkeypatch.setattr(cluster, "local_cluster", counted)
    out = tmp_path / "out"
    one = ps.fleet([str(five_recordings[0])], plant=str(NOMINAL), out=out, workers=2)
    assert asked == []
    row = one.table.to_pylist()[0]
    assert row["status"] == "ok" and row["mass_kg"] == pytest.approx(2.3213, rel=0.05)
    assert "coulomb_friction" in row["effects"]
    ps.fleet([str(p) for p in five_recordings[:3]], plant=str(NOMINAL), out=out, workers=1,
             resume=True)
    got = ps.fleet([str(p) for p in five_recordings], plant=str(NOMINAL), out=out,
                   workers=4, resume=True)
    assert asked == [1, 2]
    assert got.table.num_rows == 5 and got.table.column("status").to_pylist() == ["ok"] * 5
