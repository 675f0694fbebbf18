"""The package's Fast DDS profile: used unless the user chose a profile or another
middleware, a valid profile Fast DDS loads without a word, and in effect in the processes
the ROS verbs start."""

from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pmsm_sysid import dds

NS = "{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}"


@pytest.fixture
def clean(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> pytest.MonkeyPatch:
    for name in (*dds.PROFILE_VARIABLES, "RMW_IMPLEMENTATION"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.chdir(tmp_path)
    return monkeypatch


def test_the_profile_is_used_where_nothing_else_is_chosen(clean: pytest.MonkeyPatch) -> None:
    assert dds.use_packaged_profile()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds.PROFILE)
    assert dds.use_packaged_profile()  # a second call changes nothing
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds.PROFILE)
    clean.delenv("FASTRTPS_DEFAULT_PROFILES_FILE")
    clean.setenv("RMW_IMPLEMENTATION", "rmw_fastrtps_dynamic_cpp")
    assert dds.use_packaged_profile()


@pytest.mark.parametrize("variable", dds.PROFILE_VARIABLES)
def test_a_profile_the_user_chose_is_left_alone(clean: pytest.MonkeyPatch, tmp_path: Path,
                                                variable: str) -> None:
    mine = tmp_path / "mine.xml"
    clean.setenv(variable, str(mine))
    assert not dds.use_packaged_profile()
    assert {os.environ.get(v) for v in dds.PROFILE_VARIABLES} == {str(mine), None}


@pytest.mark.parametrize("name", dds.LOCAL_PROFILES)
def test_a_profile_in_the_working_directory_is_left_alone(clean: pytest.MonkeyPatch,
                                                          tmp_path: Path, name: str) -> None:
    (tmp_path / name).write_text("<profiles/>")
    assert not dds.use_packaged_profile()
    assert not any(os.environ.get(v) for v in dds.PROFILE_VARIABLES)


def test_another_middleware_is_left_alone(clean: pytest.MonkeyPatch) -> None:
    clean.setenv("RMW_IMPLEMENTATION", "rmw_cyclonedds_cpp")
    assert not dds.use_packaged_profile()
    assert not any(os.environ.get(v) for v in dds.PROFILE_VARIABLES)


def test_the_profile_sets_a_tenth_of_a_second_heartbeat_and_nothing_else() -> None:
    root = ET.parse(dds.PROFILE).getroot()
    writers = root.findall(f"{NS}data_writer")
    assert [w.get("is_default_profile") for w in writers] == ["true"]
    assert [child.tag for child in root] == [f"{NS}data_writer"]
    times = writers[0].findall(f"{NS}times")
    assert [child.tag for child in writers[0]] == [f"{NS}times"]
    period = times[0].find(f"{NS}heartbeatPeriod")
    assert period is not None and [child.tag for child in times[0]] == [
        f"{NS}heartbeatPeriod"]
    assert (int(period.findtext(f"{NS}sec", "")), int(period.findtext(f"{NS}nanosec", ""))) \
        == (0, 100_000_000)


@pytest.mark.ros
def test_a_ros_session_loads_it_without_a_word(tmp_path: Path) -> None:
    """In a process of its own (Fast DDS reads profiles once per process): a session of
    the verbs points Fast DDS at the profile, and Fast DDS reports no error reading it
    (it prints XML parse errors on stderr and goes on with its defaults)."""
    code = ("import os\n"
            "import rclpy\n"
            "from std_msgs.msg import String\n"
            "from pmsm_sysid.rosutil import ros_session\n"
            "with ros_session() as s:\n"
            "    node = rclpy.create_node('probe', context=s.context)\n"
            "    node.create_publisher(String, 'x', 10)\n"
            "    node.destroy_node()\n"
            "print(os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'])\n")
    env = {k: v for k, v in os.environ.items() if k not in dds.PROFILE_VARIABLES}
    env.update(ROS_LOG_DIR=str(tmp_path), ROS_DOMAIN_ID="0")
    proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str(dds.PROFILE)
    assert proc.stderr == "", proc.stderr
