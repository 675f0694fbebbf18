"""rosbag2 I/O: bags written here are stock rosbag2; reading fails with one clear BagError."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from cli_inprocess import invoke
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from pmsm_sysid.bagio import (
    FRAME_ID,
    iter_raw,
    read_recording,
    write_recording,
)
from pmsm_sysid.core.errors import BagError
from pmsm_sysid.core.recording.signals import Recording, derive_speed

STORAGES = ["mcap", "sqlite3"]
JAZZY = get_typestore(Stores.ROS2_JAZZY)


def _rec(n: int = 400, fs: float = 500.0, t0: float = 0.0, derived: bool = False) -> Recording:
    rng = np.random.default_rng(7)
    t = t0 + np.arange(n) / fs
    x = np.cumsum(rng.normal(size=n)) * 1e-4
    v = derive_speed(t, x) if derived else rng.normal(size=n)
    return Recording(t=t, thrust=rng.normal(size=n) * 10, speed=v, position=x,
                     sample_rate_hz=fs, speed_derived=derived, source="test")


def _plain_bag(path: Path, msgs: dict[str, tuple[str, list[tuple[int, object]]]],
               storage: StoragePlugin = StoragePlugin.MCAP) -> None:
    """A bag written with rosbags and the stock Jazzy typestore only (no project code)."""
    with Writer(path, version=9, storage_plugin=storage) as w:
        for topic, (msgtype, items) in msgs.items():
            conn = w.add_connection(topic, msgtype, typestore=JAZZY)
            for ns, msg in items:
                w.write(conn, ns, JAZZY.serialize_cdr(msg, msgtype))


def _header(ns: int, frame: str = "x") -> object:
    time_t = JAZZY.types["builtin_interfaces/msg/Time"]
    return JAZZY.types["std_msgs/msg/Header"](
        stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)


def _point(ns: int, x: float) -> object:
    p = JAZZY.types["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0)
    return JAZZY.types["geometry_msgs/msg/PointStamped"](header=_header(ns), point=p)


def _string(s: str) -> object:
    return JAZZY.types["std_msgs/msg/String"](data=s)


# --------------------------------------------------------------------------- stock readers


@pytest.mark.parametrize("storage", STORAGES)
def test_anyreader_reads_project_bag_without_project_code(tmp_path: Path, storage: str) -> None:
    rec = _rec(t0=1.7e9)  # wall-clock-like stamps
    bag = tmp_path / "bag"
    write_recording(bag, rec, storage=storage)
    assert (bag / "metadata.yaml").is_file()
    assert len(list(bag.glob("*.mcap" if storage == "mcap" else "*.db3"))) == 1
    ns = np.round(rec.t * 1e9).astype(np.int64)
    with AnyReader([bag]) as reader:  # no default typestore: definitions come from the bag
        assert {c.topic: c.msgtype for c in reader.connections} == {
            "/pmsm/thrust": "geometry_msgs/msg/WrenchStamped",
            "/pmsm/speed": "geometry_msgs/msg/TwistStamped",
            "/pmsm/position": "geometry_msgs/msg/PointStamped"}
        assert all(c.msgcount == len(rec) for c in reader.connections)
        got: dict[str, list[tuple[int, int, float]]] = {}
        for conn, logtime, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert msg.header.frame_id == FRAME_ID
            value = {"/pmsm/thrust": lambda m: m.wrench.force.x,
                     "/pmsm/speed": lambda m: m.twist.linear.x,
                     "/pmsm/position": lambda m: m.point.x}[conn.topic](msg)
            got.setdefault(conn.topic, []).append((logtime, stamp, value))
    for topic, signal in (("/pmsm/thrust", rec.thrust), ("/pmsm/speed", rec.speed),
                          ("/pmsm/position", rec.position)):
        logtime, stamp, value = (np.array(c) for c in zip(*got[topic], strict=True))
        np.testing.assert_array_equal(stamp.astype(np.int64), ns)
        np.testing.assert_array_equal(logtime.astype(np.int64), ns)  # receive time = stamp
        np.testing.assert_array_equal(value, signal)


@pytest.mark.parametrize("storage", STORAGES)
def test_metadata_has_qos_hash_and_custom_data(tmp_path: Path, storage: str) -> None:
    import yaml

    write_recording(tmp_path / "b", _rec(), storage=storage)
    info = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == storage
    assert info["message_count"] == 3 * 400
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        assert meta["type_description_hash"] == JAZZY.hash_rihs01(meta["type"])
        (qos,) = meta["offered_qos_profiles"]
        assert qos["reliability"] == "reliable" and qos["durability"] == "volatile"
    assert info["custom_data"]["pmsm_sysid.speed"] == "measured"
    assert info["duration"]["nanoseconds"] == 399 * 2_000_000


@pytest.mark.parametrize("storage", STORAGES)
def test_write_read_round_trip_bit_for_bit(tmp_path: Path, storage: str) -> None:
    rec = _rec(n=1000)
    write_recording(tmp_path / "b", rec, storage=storage)
    loaded = read_recording(tmp_path / "b")
    back = loaded.recording
    for name in ("t", "thrust", "speed", "position"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name), err_msg=name)
    assert back.sample_rate_hz == 500.0  # read from integer ns stamps: exact
    assert not back.speed_derived and loaded.report.n_aligned == 1000
    assert loaded.report.n_unaligned == 0 and loaded.report.n_gaps == 0
    assert back.meta["pmsm_sysid.source"] == "test"
    assert set(loaded.topics) == {"/pmsm/thrust", "/pmsm/speed", "/pmsm/position"}


def test_derived_speed_not_stored_and_rederived(tmp_path: Path) -> None:
    rec = _rec(derived=True)
    write_recording(tmp_path / "b", rec, extra_points={"reference": rec.position * 2})
    with AnyReader([tmp_path / "b"]) as reader:
        assert sorted(c.topic for c in reader.connections) == ["/pmsm/position",
                                                               "/pmsm/reference", "/pmsm/thrust"]
    import yaml

    info = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())
    custom = info["rosbag2_bagfile_information"]["custom_data"]
    assert custom["pmsm_sysid.speed"].startswith("absent: derived")
    loaded = read_recording(tmp_path / "b")
    assert loaded.recording.speed_derived and loaded.report.speed_derived
    np.testing.assert_array_equal(loaded.recording.speed, rec.speed)


def test_namespace_detection_and_choice(tmp_path: Path) -> None:
    write_recording(tmp_path / "one", _rec(), namespace="/axis1")
    assert read_recording(tmp_path / "one").recording.meta["input_topics"].startswith("/axis1/")
    # two namespaces in one bag: ambiguous unless one is chosen
    pts = [(k * 2_000_000, _point(k * 2_000_000, float(k))) for k in range(10)]
    wr = JAZZY.types["geometry_msgs/msg/WrenchStamped"]
    vec, wrench = JAZZY.types["geometry_msgs/msg/Vector3"], JAZZY.types["geometry_msgs/msg/Wrench"]
    thr = [(ns, wr(header=_header(ns), wrench=wrench(force=vec(x=-p.point.x, y=0.0, z=0.0),
                                                       torque=vec(x=0.0, y=0.0, z=0.0))))
           for ns, p in pts]
    _plain_bag(tmp_path / "two", {
        "/a/thrust": ("geometry_msgs/msg/WrenchStamped", thr),
        "/a/position": ("geometry_msgs/msg/PointStamped", pts),
        "/b/thrust": ("geometry_msgs/msg/WrenchStamped", thr),
        "/b/position": ("geometry_msgs/msg/PointStamped", pts)})
    with pytest.raises(BagError, match="several input namespaces"):
        read_recording(tmp_path / "two")
    rec = read_recording(tmp_path / "two", namespace="/b").recording
    assert rec.speed_derived and len(rec) == 10
    np.testing.assert_array_equal(rec.thrust, -rec.position)


def _joint_bag(path: Path, names: list[str], n: int = 50, velocity: bool = True) -> None:
    js = JAZZY.types["sensor_msgs/msg/JointState"]
    items = []
    for k in range(n):
        ns = 1_000_000 * k
        m = len(names)
        items.append((ns, js(header=_header(ns), name=names,
                             position=np.arange(m) + 0.001 * k,
                             velocity=(np.arange(m) + 10.0 * k) if velocity else np.zeros(0),
                             effort=np.arange(m) - 5.0 * k)))
    _plain_bag(path, {"/joint_states": ("sensor_msgs/msg/JointState", items)})


def test_joint_state_layout(tmp_path: Path) -> None:
    _joint_bag(tmp_path / "j2", ["left", "right"])
    with pytest.raises(BagError, match="carries joints left, right"):
        read_recording(tmp_path / "j2")
    rec = read_recording(tmp_path / "j2", joint_name="right").recording
    k = np.arange(50)
    np.testing.assert_array_equal(rec.position, 1 + 0.001 * k)
    np.testing.assert_array_equal(rec.speed, 1 + 10.0 * k)
    np.testing.assert_array_equal(rec.thrust, 1 - 5.0 * k)
    assert rec.sample_rate_hz == 1000.0 and not rec.speed_derived
    with pytest.raises(BagError, match="no joint 'elbow'"):
        read_recording(tmp_path / "j2", joint_name="elbow")
    _joint_bag(tmp_path / "j1", ["axis"], velocity=False)
    one = read_recording(tmp_path / "j1").recording
    assert one.speed_derived and len(one) == 50


@pytest.mark.parametrize("storage", STORAGES)
def test_iter_raw_log_order_and_bytes(tmp_path: Path, storage: str) -> None:
    rec = _rec(n=50)
    write_recording(tmp_path / "b", rec, storage=storage)
    raws = list(iter_raw(tmp_path / "b"))
    assert len(raws) == 150
    assert [r.timestamp_ns for r in raws] == sorted(r.timestamp_ns for r in raws)
    with AnyReader([tmp_path / "b"]) as reader:
        ref = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert sorted(ref) == sorted((r.topic, r.timestamp_ns, r.data) for r in raws)
    only = list(iter_raw(tmp_path / "b", topics=["/pmsm/position"]))
    assert len(only) == 50 and {r.msgtype for r in only} == {"geometry_msgs/msg/PointStamped"}
    assert list(iter_raw(tmp_path / "b", topics=[])) == []
    with pytest.raises(BagError, match=r"no topic /nope \(topics: /pmsm/position"):
        list(iter_raw(tmp_path / "b", topics=["/nope"]))


# --------------------------------------------------------------------------- bad bags


def _good(tmp_path: Path, storage: str = "mcap") -> Path:
    bag = tmp_path / f"good_{storage}"
    write_recording(bag, _rec(n=2000), storage=storage)
    return bag


def _one_line(exc: pytest.ExceptionInfo[BagError]) -> str:
    text = str(exc.value)
    assert "\n" not in text and "Traceback" not in text
    return text


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    bag = _good(tmp_path)
    with pytest.raises(BagError, match="exists already"):
        write_recording(bag, _rec())
    with pytest.raises(BagError, match="unknown storage 'zip'"):
        write_recording(tmp_path / "z", _rec(), storage="zip")


@pytest.mark.parametrize("case,pattern", [
    ("missing", "no such bag"),
    ("empty_dir", r"not a rosbag2 directory \(no metadata.yaml\)"),
    ("text_file", "not a rosbag2 directory or .mcap/.db3 file"),
    ("garbage_yaml", "corrupt metadata.yaml"),
    ("missing_key", "corrupt metadata.yaml"),
    ("unknown_plugin", "unknown storage plugin"),
    ("no_metadata", "no metadata.yaml beside good_mcap.mcap: not finalised"),
    ("missing_storage_file", "storage file.* listed in metadata.yaml are missing"),
])
def test_bad_bag_layouts(tmp_path: Path, case: str, pattern: str) -> None:
    target = tmp_path / "bad"
    if case == "empty_dir":
        target.mkdir()
    elif case == "text_file":
        target = tmp_path / "notes.txt"
        target.write_text("hello")
    elif case != "missing":
        target = _good(tmp_path)
        meta = target / "metadata.yaml"
        text = meta.read_text()
        if case == "garbage_yaml":
            meta.write_text("rosbag2_bagfile_information: [unclosed\n  - : :")
        elif case == "missing_key":
            meta.write_text(text.replace("storage_identifier", "storage_id"))
        elif case == "unknown_plugin":
            meta.write_text(text.replace("storage_identifier: mcap", "storage_identifier: zip"))
        elif case == "no_metadata":
            meta.unlink()
        elif case == "missing_storage_file":
            next(target.glob("*.mcap")).unlink()
    with pytest.raises(BagError) as exc:
        read_recording(target)
    assert pattern and __import__("re").search(pattern, _one_line(exc)), str(exc.value)


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("cut", [0.5, 0.999])
def test_truncated_storage(tmp_path: Path, storage: str, cut: float) -> None:
    bag = _good(tmp_path, storage)
    data = next(bag.glob("*.mcap" if storage == "mcap" else "*.db3"))
    blob = data.read_bytes()
    data.write_bytes(blob[: int(len(blob) * cut)])
    with pytest.raises(BagError) as exc:
        read_recording(bag)
    text = _one_line(exc)
    assert str(bag) in text and ("corrupt" in text or "truncated" in text)


@pytest.mark.parametrize("storage", STORAGES)
def test_garbage_storage(tmp_path: Path, storage: str) -> None:
    bag = _good(tmp_path, storage)
    data = next(bag.glob("*.mcap" if storage == "mcap" else "*.db3"))
    data.write_bytes(os.urandom(4096))
    with pytest.raises(BagError, match="corrupt"):
        read_recording(bag)


def _read_as_nobody(bag: Path) -> str:
    """Try read_recording without root rights (fork + setuid when run as root)."""
    if os.geteuid() != 0:
        try:
            read_recording(bag)
        except BagError as exc:
            return str(exc)
        return "read succeeded"
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: drop to nobody, report the outcome through the pipe
        os.close(r)
        try:
            os.setgid(65534)
            os.setuid(65534)
            read_recording(bag)
            out = "read succeeded"
        except BagError as exc:
            out = str(exc)
        except BaseException as exc:  # anything else is a failure of the contract
            out = f"UNEXPECTED {type(exc).__name__}: {exc}"
        os.write(w, out.encode())
        os._exit(0)
    os.close(w)
    with os.fdopen(r) as f:
        out = f.read()
    os.waitpid(pid, 0)
    return out


@pytest.fixture
def open_tmp() -> Iterator[Path]:
    """A world-searchable temporary directory (pytest's tmp_path sits under a 0700 one)."""
    path = Path(tempfile.mkdtemp(prefix="pmsm_bagio_"))
    path.chmod(0o755)
    try:
        yield path
    finally:
        for p in (path, *path.rglob("*")):
            p.chmod(0o755)
        shutil.rmtree(path)


@pytest.mark.parametrize("what", ["dir", "file", "metadata", "parent"])
def test_unreadable_permissions(open_tmp: Path, what: str) -> None:
    parent = open_tmp / "parent"
    parent.mkdir()
    bag = _good(parent)
    target = {"dir": bag, "file": next(bag.glob("*.mcap")), "metadata": bag / "metadata.yaml",
              "parent": parent}
    target[what].chmod(0o000)
    out = _read_as_nobody(bag)
    assert out.startswith(f"{bag}: permission denied"), out
    assert "\n" not in out


def test_missing_input_topics_lists_what_is_there(tmp_path: Path) -> None:
    pts = [(k * 1000, _point(k * 1000, 1.0)) for k in range(5)]
    _plain_bag(tmp_path / "b", {"/pmsm/position": ("geometry_msgs/msg/PointStamped", pts),
                                "/chatter": ("std_msgs/msg/String", [(0, _string("hi"))])})
    with pytest.raises(BagError) as exc:
        read_recording(tmp_path / "b")
    text = _one_line(exc)
    assert "no <ns>/thrust + <ns>/position" in text
    assert "/chatter (std_msgs/msg/String)" in text and "/pmsm/position" in text
    with pytest.raises(BagError, match="no /pmsm/thrust topic"):
        read_recording(tmp_path / "b", namespace="/pmsm")


def test_wrong_message_type_on_topic(tmp_path: Path) -> None:
    pts = [(k * 1000, _point(k * 1000, 1.0)) for k in range(5)]
    _plain_bag(tmp_path / "b", {"/pmsm/position": ("geometry_msgs/msg/PointStamped", pts),
                                "/pmsm/thrust": ("std_msgs/msg/String", [(0, _string("x"))])})
    with pytest.raises(BagError, match="/pmsm/thrust has type std_msgs/msg/String, expected "
                                       "geometry_msgs/msg/WrenchStamped"):
        read_recording(tmp_path / "b")


@pytest.mark.parametrize("verb", ["identify", "import-mat"])
def test_bad_inputs_exit_2_with_one_line_from_cli(tmp_path: Path, verb: str) -> None:
    """Through the command line (``pmsm_sysid.cli.main`` in this process, its exit status,
    stdout and stderr as the console script gives them; the console script itself exits 2
    as a process in test_import_mat.py and test_install.py): a directory that is neither a
    bag nor a .mat file."""
    (tmp_path / "notabag").mkdir()
    extra = ["--out", str(tmp_path / "o")] if verb == "import-mat" else []
    out = invoke(verb, str(tmp_path / "notabag"), *extra)
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr
    if verb == "identify":
        assert "not a rosbag2 directory (no metadata.yaml)" in out.stderr


def test_bad_stamps_refused_and_nonfinite_values_counted(tmp_path: Path) -> None:
    rec = _rec(n=100)
    for t in (rec.t - 1.0, np.where(np.arange(100) == 5, np.nan, rec.t), rec.t + 2.0**31):
        bad = Recording(t=t, thrust=rec.thrust, speed=rec.speed, position=rec.position,
                        sample_rate_hz=500.0)
        with pytest.raises(BagError, match="stamps must be finite seconds"):
            write_recording(tmp_path / "bad", bad)
        assert not (tmp_path / "bad").exists()
    thrust = rec.thrust.copy()
    thrust[[10, 20]] = [np.nan, -np.inf]
    write_recording(tmp_path / "nan", Recording(t=rec.t, thrust=thrust, speed=rec.speed,
                                                position=rec.position, sample_rate_hz=500.0))
    loaded = read_recording(tmp_path / "nan")
    assert loaded.report.n_nonfinite == 2 and loaded.report.n_aligned == 98
    assert loaded.report.n_unaligned == 4 and loaded.report.n_gaps == 2
    assert np.all(np.isfinite(loaded.recording.thrust))


def test_unstamped_publisher_is_named(tmp_path: Path) -> None:
    from pmsm_sysid.core.errors import DataError

    rec = _rec(n=50)
    unstamped = Recording(t=np.zeros(50), thrust=rec.thrust, speed=rec.speed,
                          position=rec.position, sample_rate_hz=500.0)
    write_recording(tmp_path / "b", unstamped)
    with pytest.raises(DataError, match="same on every position message"):
        read_recording(tmp_path / "b")
