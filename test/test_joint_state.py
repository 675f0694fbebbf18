"""A ros2_control robot's recording: ``sensor_msgs/JointState`` on ``/joint_states`` (where the
joint_state_broadcaster publishes), several joints in each message.

``replay`` of such a bag publishes on the recorded topic; the identifier with only
``input_layout: joint_state`` and ``joint_name`` takes every sample, and its models are the
offline fits of the same bag; a namespaced robot is one remap away. ``identify`` and
``diagnose`` (and ``fit-plant``) read the same bag (``--joint`` names the axis among
several joints).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_inprocess import invoke
from replay_helpers import (
    assert_live_equals_offline,
    fast,
    replay_into_pipeline,
    write_joint_state_bag,
)

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant

REPO = Path(__file__).resolve().parents[1]
N = 2500
JOINTS = ("gripper", "axis", "wrist")
ONLY_THE_LAYOUT = {"input_layout": "joint_state", "joint_name": "axis"}
H1_ONLY = {"orders": [1]}  # the GFRF node's cheapest analysis: this test is about the inputs
#: the bag is replayed faster than real time (the models are compared, not the timing): the
#: windows come faster than they are fitted, and the identifier's queue holds them all
QUEUE_ALL = {"queue_size": 16}


def _recording() -> Any:
    plant = load_plant("drive")  # the Table 1 motor as a drive measures it (run's default)
    return simulate(plant, make_excitation("multisine", N, plant.sample_rate_hz, seed=5),
                    seed=5)


def _env(ros_env: int, tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "ROS_DOMAIN_ID": str(ros_env), "ROS_LOG_DIR": str(tmp_path / "log"),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def _check_every_sample_and_the_offline_models(run: Any, bag: Path, topic: str,
                                               subscribers: str = "1 subscriber") -> None:
    from pmsm_sysid.bagio import read_recording

    s = run.summary
    assert s["samples_received"] == N, (s["inputs"], run.replay_out)
    assert s["samples_dropped"] == 0 and s["samples_missing"] == 0 and s["unaligned"] == 0
    assert s["inputs"]["expected"] == [topic] and s["inputs"]["problem"] is None
    assert s["inputs"]["arrived"][topic]["messages"] == N
    assert f"{topic} {N} to {subscribers})" in run.replay_out
    # the results are published under the pipeline's namespace (/pmsm), where its collector
    # listens; each is the offline fit of the joint's samples in the bag
    assert run.models
    rec = read_recording(bag, joint_name="axis").recording
    for m in run.models[-4:]:
        assert_live_equals_offline(m, rec, m["window"]["start_index"], m["window"]["stop_index"])


@pytest.mark.ros
@pytest.mark.slow
def test_replayed_ros2_control_bag_reaches_the_identifier_with_the_layout_alone(
        ros_context: Any, ros_env: int, tmp_path: Path) -> None:
    bag = write_joint_state_bag(_recording(), tmp_path / "robot", joints=JOINTS)
    run = replay_into_pipeline(bag, _env(ros_env, tmp_path), ros_context, N,
                               replay_args=("--wait", "30", *fast(N)), deadline_s=120,
                               identifier_params=ONLY_THE_LAYOUT | QUEUE_ALL,
                               gfrf_params=H1_ONLY)
    _check_every_sample_and_the_offline_models(run, bag, "/joint_states")


@pytest.mark.ros
@pytest.mark.slow
def test_namespaced_robot_is_one_remap_away_and_recorded(ros_env: int, tmp_path: Path) -> None:
    """``--ros-args -r /joint_states:=/robot1/joint_states``; ``--record`` records the topic
    the identifier listens to (and the results under the pipeline's namespace)."""
    from rosbags.highlevel import AnyReader

    bag = write_joint_state_bag(_recording(), tmp_path / "robot1", joints=JOINTS,
                                topic="/robot1/joint_states")
    remap = ["--ros-args", "-r", "/joint_states:=/robot1/joint_states"]
    live = tmp_path / "live"
    run = replay_into_pipeline(bag, _env(ros_env, tmp_path), None, N,
                               replay_args=("--wait", "30", "--subscribers", "2",
                                            *fast(N)),
                               deadline_s=120, identifier_params=ONLY_THE_LAYOUT | QUEUE_ALL,
                               gfrf_params=H1_ONLY, domain_id=ros_env, ros_args=remap,
                               record=str(live))
    _check_every_sample_and_the_offline_models(run, bag, "/robot1/joint_states",
                                               "2 subscribers")
    s = run.summary
    assert s["record_error"] is None and s["record_samples_lost"] == 0, s["record_error"]
    with AnyReader([live]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/robot1/joint_states"] == N
    assert counts["/pmsm/model"] == s["models_published"] > 0
    assert s["recorded_by_topic"] == counts


@pytest.mark.slow
def test_identify_and_diagnose_read_the_robots_bag(tmp_path: Path) -> None:
    """The offline verbs find the JointState layout by themselves; among several joints
    ``--joint`` names the axis, and the numbers are those of the same samples on the three
    input topics."""
    import pmsm_sysid as ps
    from pmsm_sysid.bagio import write_recording

    rec = _recording()
    robot = write_joint_state_bag(rec, tmp_path / "robot", joints=JOINTS)
    single = write_joint_state_bag(rec, tmp_path / "single")
    topics = tmp_path / "topics"
    write_recording(topics, rec)

    several = invoke("identify", str(robot))
    assert several.returncode == 2 and several.stderr.count("\n") == 1
    assert "carries joints axis, gripper, wrist" in several.stderr
    assert "--joint axis" in several.stderr

    small = {"ny": 4, "nu": 4, "terms": 6, "validate": (1500, 2500)}
    out = tmp_path / "robot.json"
    proc = invoke("identify", str(robot), "--joint", "axis", "--ny", "4", "--nu", "4",
                "--terms", "6", "--validate", "1500:2500", "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    fits = {"robot": json.loads(out.read_text()),
            "single": ps.identify(single, **small).to_dict(),  # one joint: found by itself
            "topics": ps.identify(topics, **small).to_dict()}
    for name in ("robot", "single"):
        assert [t["name"] for t in fits[name]["terms"]] == \
            [t["name"] for t in fits["topics"]["terms"]]
        np.testing.assert_allclose([t["estimate"] for t in fits[name]["terms"]],
                                   [t["estimate"] for t in fits["topics"]["terms"]],
                                   rtol=1e-12, atol=0)
    with pytest.raises(ps.PmsmSysidError, match="not a JointState topic"):
        ps.read_bag(topics, joint="axis")
    with pytest.raises(ps.PmsmSysidError, match="no joint 'elbow'"):
        ps.read_bag(robot, joint="elbow")

    out = tmp_path / "diag.json"
    proc = invoke("diagnose", "--plant", "drive", "--real", str(robot), "--joint", "axis",
                "--no-replay", "--no-gfrf", "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    found = json.loads(out.read_text())
    assert found["effects"] == []  # the recording's own plant: nothing missing
    same = ps.diagnose("drive", topics, replay=False, gfrf=False).to_dict()
    assert found["mismatch"] == same["mismatch"] and found["fit"] == same["fit"]
    with pytest.raises(ps.PmsmSysidError, match="no joint 'elbow'"):  # read the same way
        ps.fit_plant(robot, joint="elbow")
