"""``--ros-args`` after a ROS verb's options: params files, ``-p`` and remaps go to rclpy."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pmsm_sysid.core.errors import PmsmSysidError
from pmsm_sysid.rosargs import check_ros_args, prepared, split_ros_args

RUN = ["run", "--nodes", "sim,identifier", "--outputs", "speed", "--clock", "sim",
       "--duration", "4", "--json", "-"]


def test_split_keeps_the_verbs_options_and_hands_the_rest_to_ros() -> None:
    own, ros = split_ros_args(["run", "--duration", "3", "--ros-args", "-p", "hop:=5",
                               "--params-file", "p.yaml"])
    assert own == ["run", "--duration", "3"]
    assert ros == ["--ros-args", "-p", "hop:=5", "--params-file", "p.yaml"]
    own, ros = split_ros_args(["run", "--ros-args", "-r", "__ns:=/b", "--", "--json", "-"])
    assert own == ["run", "--json", "-"] and ros == ["--ros-args", "-r", "__ns:=/b"]
    assert split_ros_args(["run", "--json", "-"]) == (["run", "--json", "-"], [])


def test_bare_node_sections_name_the_node_in_the_pipelines_namespace(tmp_path: Path) -> None:
    import yaml

    f = tmp_path / "p.yaml"
    f.write_text("pmsm_identifier:\n  ros__parameters:\n    hop: 125\n"
                 "/**:\n  ros__parameters:\n    queue_size: 3\n")
    with prepared(["--ros-args", "--params-file", str(f)], "/axis2") as args:
        data = yaml.safe_load(Path(args[2]).read_text())
        assert data == {"/axis2/pmsm_identifier": {"ros__parameters": {"hop": 125}},
                        "/**": {"ros__parameters": {"queue_size": 3}}}
    with prepared(["--ros-args", "-r", "__ns:=/c", "--params-file", str(f)], "/axis2") as args:
        assert "/c/pmsm_identifier" in yaml.safe_load(Path(args[4]).read_text())
    g = tmp_path / "q.yaml"
    g.write_text("/**/pmsm_identifier:\n  ros__parameters:\n    hop: 125\n")
    with prepared(["--ros-args", "--params-file", str(g)], "/axis2") as args:
        assert args[2] == str(g)  # nothing to move: the file is given to ROS as it is


def test_a_temporary_copy_exists_only_while_a_file_needs_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without a file to rewrite nothing is made (a verb killed by SIGKILL cannot clean up
    after itself); a rewritten file's copy is gone when the verb ends."""
    import tempfile

    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    as_is = tmp_path / "q.yaml"
    as_is.write_text("/**/pmsm_identifier:\n  ros__parameters:\n    hop: 125\n")
    with prepared(["--ros-args", "-p", "hop:=5", "--params-file", str(as_is)], "/a"):
        assert list(scratch.iterdir()) == []
    bare = tmp_path / "p.yaml"
    bare.write_text("pmsm_identifier:\n  ros__parameters:\n    hop: 125\n")
    with prepared(["--ros-args", "--params-file", str(bare), "--params-file", str(bare)],
                  "/a") as args:
        made = list(scratch.iterdir())
        assert len(made) == 1 and {Path(args[2]).parent, Path(args[4]).parent} == set(made)
    assert list(scratch.iterdir()) == []


@pytest.mark.parametrize("args,match", [
    (["--ros-args", "--params-file", "/no/such.yaml"], "no such file"),
    (["--ros-args", "-p", "hop"], "name:=value"),
    (["--ros-args", "-p"], "needs a value"),
])
def test_bad_ros_args_are_found_before_any_work(args: list[str], match: str) -> None:
    with pytest.raises(PmsmSysidError, match=match):
        check_ros_args(args)


@pytest.mark.ros
@pytest.mark.slow
def test_a_params_file_sets_the_identifiers_hop(ros_env: int, tmp_path: Path,
                                                capfd: pytest.CaptureFixture[str]) -> None:
    """The same 4 s of data: hop 250 (default) fits 4 windows, hop 125 from the params file
    8, and ``-p`` after it wins (hop 500: 2); the verb's own --hop wins over both. Each run
    is ``main`` in this process (a context of its own, parsed from its ``--ros-args``): the
    arguments are what is checked, not the process."""
    from reliability_helpers import ros_verb

    params = tmp_path / "params.yaml"
    params.write_text("pmsm_identifier:\n  ros__parameters:\n    hop: 125\n")

    def fitted(*extra: str) -> tuple[int, int]:
        proc = ros_verb(capfd, *RUN, *extra)
        assert proc.returncode == 0, proc.stderr
        s = json.loads(proc.stdout)
        assert s["samples_received"] == 2000 and s["windows_skipped"] == 0
        return s["windows_fitted"], s["windows_due"]

    assert fitted() == (4, 4)
    assert fitted("--ros-args", "--params-file", str(params)) == (8, 8)
    assert fitted("--ros-args", "--params-file", str(params), "-p", "hop:=500") == (2, 2)
    assert fitted("--hop", "250", "--ros-args", "--params-file", str(params)) == (4, 4)


@pytest.mark.ros
def test_ros_args_errors_are_one_line_and_exit_2(ros_env: int, tmp_path: Path,
                                                 capfd: pytest.CaptureFixture[str]) -> None:
    """Refused before any work: in this process (reliability_helpers.ros_verb)."""
    from reliability_helpers import ros_verb

    for argv, match in (
            (["run", "--ros-args", "--params-file", str(tmp_path / "none.yaml")],
             "no such file"),
            (["monitor", "--once", "--ros-args", "-r", "nonsense"], "name:=value"),
            (["identify", "x.bag", "--ros-args", "-p", "a:=1"], "ROS verbs only")):
        proc = ros_verb(capfd, *argv)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and match in lines[0], proc.stderr


def test_the_readme_lists_every_topic_with_its_type() -> None:
    """The topic table of the README is in step with the code's topic names and types."""
    from pmsm_sysid.topics import (
        DIAGNOSIS_COUNTS,
        DIAGNOSIS_PARAMS,
        INPUT_TYPES,
        OUTPUT_TYPES,
        STAT_TOPICS,
    )

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    rows = {f"`<ns>/{n}` | `{t}`" for n, t in {**INPUT_TYPES, **OUTPUT_TYPES}.items()}
    rows |= {f"`<ns>/stats/<output>/{q}` | `{t}` | {u} |" for q, (t, u, _) in
             STAT_TOPICS.items()}
    rows.add("`/diagnostics` | `diagnostic_msgs/msg/DiagnosticArray`")
    rows |= {f"`<ns>/stats/diagnosis/{q}` | `{t}` | {u} |" for q, (t, u, _) in
             DIAGNOSIS_COUNTS.items()}
    rows |= {f"| `{effect}` | " + ", ".join(f"`{p}` ({u})" for p, u in params) + " |"
             for effect, params in DIAGNOSIS_PARAMS.items()}
    missing = [r for r in rows if r not in readme]
    assert not missing, missing


@pytest.mark.ros
def test_remaps_and_params_reach_every_node_of_the_pipeline(ros_env: int, tmp_path: Path) -> None:
    """``-r __ns:=`` moves the whole pipeline, a relative ``-r`` renames one topic, and a
    params file's ``/**`` section reaches every node that has the parameter."""
    from pmsm_sysid.app import build_pipeline

    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    publish_period_s: 0.2\n")
    args = ["--ros-args", "-r", "__ns:=/moved", "-r", "model:=model_raw",
            "--params-file", str(params)]
    with build_pipeline(["sim", "identifier", "gfrf"], clock="sim", domain_id=ros_env,
                        ros_args=args, identifier_params={"outputs": ["speed"]}) as pipe:
        ident, gfrf = pipe.identifier, pipe.gfrf
        assert ident.get_fully_qualified_name() == "/moved/pmsm_identifier"
        assert gfrf.get_fully_qualified_name() == "/moved/pmsm_gfrf"
        assert {p.topic_name for p in pipe.sim.input_publishers} == {
            "/moved/thrust", "/moved/speed", "/moved/position"}
        assert ident.resolve_topic_name("model") == "/moved/model_raw"
        for node in (ident, gfrf):
            assert node.get_parameter("publish_period_s").value == 0.2
        pipe.run(3.0)
        pipe.finish()
        assert ident.models_published >= 2 and gfrf.received == ident.models_published
