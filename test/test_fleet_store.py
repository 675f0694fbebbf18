"""The fleet's inputs and its table on disk (no Dask, no fitting): recordings found from
paths, directories and glob patterns; one unit of work per axis of a recording; a content
key that ignores names; the output directory's rules; the Parquet table kept readable row
by row and read back for a resumed batch."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

import pmsm_sysid as ps
from pmsm_sysid.bagio import list_axes, read_recording
from pmsm_sysid.batch.inputs import content_key, expand, units_of
from pmsm_sysid.batch.store import (
    MANIFEST,
    PARTS,
    RESULTS,
    Store,
    check_out_dir,
    from_table,
    schema,
    to_table,
)
from pmsm_sysid.core.errors import OptionError, OutputError
from pmsm_sysid.core.fleet import columns, empty_row

JAZZY = get_typestore(Stores.ROS2_JAZZY)
MANIFEST_A = {"tool": "pmsm-sysid fleet", "plant": "a.yaml",
              "reference": {"plant_sha256": "aa"}, "options": {"alpha": 0.001}}


def _bag(path: Path, seed: int = 0, duration: float = 0.2, namespace: str = "/pmsm") -> Path:
    return ps.write_bag(ps.simulate(duration=duration, seed=seed), path, namespace=namespace)


def _header(ns: int) -> object:
    t = JAZZY.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return JAZZY.types["std_msgs/msg/Header"](stamp=t, frame_id="x")


def _two_axes_and_two_joints(path: Path) -> None:
    """/a and /b (thrust + position each), and a JointState topic with joints j1, j2."""
    point = JAZZY.types["geometry_msgs/msg/PointStamped"]
    wrench = JAZZY.types["geometry_msgs/msg/WrenchStamped"]
    vec = JAZZY.types["geometry_msgs/msg/Vector3"]
    js = JAZZY.types["sensor_msgs/msg/JointState"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for ns in ("/a", "/b"):
            conns[ns + "/thrust"] = w.add_connection(ns + "/thrust", wrench.__msgtype__,
                                                     typestore=JAZZY)
            conns[ns + "/position"] = w.add_connection(ns + "/position", point.__msgtype__,
                                                       typestore=JAZZY)
        joints = w.add_connection("/robot/joint_states", js.__msgtype__, typestore=JAZZY)
        for k in range(20):
            stamp = 2_000_000 * k
            for ns in ("/a", "/b"):
                f = wrench(header=_header(stamp), wrench=JAZZY.types[
                    "geometry_msgs/msg/Wrench"](force=vec(x=float(k), y=0.0, z=0.0),
                                                torque=vec(x=0.0, y=0.0, z=0.0)))
                p = point(header=_header(stamp), point=JAZZY.types["geometry_msgs/msg/Point"](
                    x=0.001 * k, y=0.0, z=0.0))
                w.write(conns[ns + "/thrust"], stamp,
                        JAZZY.serialize_cdr(f, wrench.__msgtype__))
                w.write(conns[ns + "/position"], stamp,
                        JAZZY.serialize_cdr(p, point.__msgtype__))
            m = js(header=_header(stamp), name=["j1", "j2"], position=np.array([0.1 * k, 1.0]),
                   velocity=np.array([0.1, 0.0]), effort=np.array([float(k), -1.0]))
            w.write(joints, stamp, JAZZY.serialize_cdr(m, js.__msgtype__))


# --------------------------------------------------------------------------- recordings


def test_recordings_from_paths_directories_and_globs(tmp_path: Path) -> None:
    day1, day2 = tmp_path / "fleet" / "day1", tmp_path / "fleet" / "day2"
    day1.mkdir(parents=True)
    day2.mkdir()
    a = _bag(day1 / "axis_a", 1)
    b = _bag(day1 / "axis_b", 2)
    c = _bag(day2 / "axis_a", 3)
    (day2 / "notes.txt").write_text("not a recording")
    assert expand([str(tmp_path / "fleet")]) == [a, b, c]  # searched, in name order
    assert expand([str(tmp_path / "fleet" / "*" / "axis_a")]) == [a, c]
    assert expand([str(c), str(tmp_path / "fleet" / "**" / "axis_*")]) == [c, a, b]
    mcap = next(a.glob("*.mcap"))
    assert expand([str(mcap)]) == [mcap]  # one storage file is a recording too


@pytest.mark.parametrize("args", [[], ["{tmp}/nothing"], ["{tmp}/empty"], ["{tmp}/*.bag"],
                                  ["{tmp}/file.txt"]])
def test_an_argument_naming_no_recording_is_refused(tmp_path: Path, args: list[str]) -> None:
    (tmp_path / "empty").mkdir()
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(OptionError) as info:
        expand([a.format(tmp=tmp_path) for a in args])
    assert "\n" not in str(info.value)
    assert ("no recordings given" if not args else args[0].format(tmp=tmp_path)) in \
        str(info.value)


def test_the_content_key_ignores_names_and_sees_every_byte(tmp_path: Path) -> None:
    a = _bag(tmp_path / "a", 1)
    renamed = tmp_path / "elsewhere" / "b"
    renamed.parent.mkdir()
    shutil.copytree(a, renamed)
    assert content_key(a) == content_key(renamed)
    assert content_key(a) != content_key(_bag(tmp_path / "c", 2))
    data = next(renamed.glob("*.mcap"))
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 2] ^= 1
    data.write_bytes(bytes(raw))
    assert content_key(a) != content_key(renamed)


def test_every_axis_of_a_recording_is_a_unit_of_work(tmp_path: Path) -> None:
    _two_axes_and_two_joints(tmp_path / "multi")
    assert list_axes(tmp_path / "multi") == [("/a", None), ("/b", None),
                                               ("/robot/joint_states", "j1"),
                                               ("/robot/joint_states", "j2")]
    units = units_of(tmp_path / "multi")
    assert [u.axis for u in units] == ["/a", "/b", "j1", "j2"]
    assert len({u.key for u in units}) == 4 and len({u.content for u in units}) == 1
    j2 = read_recording(tmp_path / "multi", namespace="/robot/joint_states",
                        joint_name="j2").recording
    assert np.all(j2.thrust == -1.0) and np.all(j2.position == 1.0)
    only = units_of(tmp_path / "multi", namespace="/b")
    assert [(u.namespace, u.axis) for u in only] == [("/b", "/b")]
    parent = units_of(tmp_path / "multi", axis_from="parent")
    assert [u.axis for u in parent] == [f"{tmp_path.name}:{x}" for x in ("/a", "/b", "j1",
                                                                         "j2")]
    (tmp_path / "axis07").mkdir()
    one = _bag(tmp_path / "axis07" / "monday", 1)
    assert [u.axis for u in units_of(one, axis_from="parent")] == ["axis07"]


def test_a_recording_that_cannot_be_opened_is_still_a_unit(tmp_path: Path) -> None:
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    (broken / "broken_0.mcap").write_bytes(b"\x89MCAP0\r\n garbage")
    (unit,) = units_of(broken)
    assert unit.axis is None and unit.path == str(broken)  # its row will say why


# --------------------------------------------------------------------------- the table


def _row(i: int, status: str = "ok", **more: object) -> dict[str, object]:
    row = empty_row()
    row.update(recording=f"r{i}", axis="/a", start_time=1.7e9 + i * 86400.0 + 0.123456,
               duration_s=10.0, sample_rate_hz=500.0, status=status, mass_kg=2.3 + i,
               content_sha256=f"c{i}", namespace="/a", analysed_at=1.8e9,
               effects=["cogging"], diagnosed=[], samples=5000, speed_derived=False,
               **{"cogging.amplitude_n": 1.0, "cogging.harmonics": [
                   {"order": 2, "amplitude_n": 0.5, "phase_rad": 0.1}],
                  "cogging.confidence": "high"})
    row.update(more)
    return row


def test_rows_round_trip_through_parquet(tmp_path: Path) -> None:
    rows = [_row(1), _row(2, "error", error="r2: too short", mass_kg=None)]
    table = to_table(rows)
    assert table.schema == schema() and table.column_names == columns()
    assert table.schema.field("start_time").type == pa.timestamp("us", tz="UTC")
    pq.write_table(table, tmp_path / "t.parquet")
    back = from_table(pq.read_table(tmp_path / "t.parquet"))
    assert back[0]["start_time"] == pytest.approx(rows[0]["start_time"], abs=1e-6)
    for got, want in zip(back, rows, strict=True):
        for k in columns():
            if k != "start_time" and k != "analysed_at":
                assert got[k] == want[k], k
    # plain pyarrow gives datetimes (UTC) without pandas
    first = pq.read_table(tmp_path / "t.parquet").to_pylist()[0]["start_time"]
    assert first.tzinfo is not None and first.timestamp() == pytest.approx(rows[0]["start_time"])


def test_the_store_keeps_every_row_on_disk_and_reads_them_back(tmp_path: Path) -> None:
    out = tmp_path / "out"
    store = Store(out)
    store.open(MANIFEST_A, resume=False)
    store.add(_row(1))
    store.flush()
    store.add(_row(2))  # on disk as its part, not yet in the table: as if killed now
    assert pq.read_table(out / RESULTS).num_rows == 1  # always a whole, readable table
    assert len(list((out / PARTS).glob("*.parquet"))) == 2
    again = Store(out)
    again.open(MANIFEST_A, resume=True)
    assert again.done() == {"c1:/a:", "c2:/a:"}
    assert pq.read_table(out / RESULTS).num_rows == 2
    again.add(_row(2, mass_kg=9.9))  # a row analysed again replaces the old one
    again.add(_row(3, "error", error="r3: empty"))
    again.close()
    assert not (out / PARTS).exists()
    table = pq.read_table(out / RESULTS)
    assert table.column("recording").to_pylist() == ["r1", "r2", "r3"]
    assert table.column("mass_kg").to_pylist()[1] == 9.9
    third = Store(out)
    third.open(MANIFEST_A, resume=True)
    assert third.done() == {"c1:/a:", "c2:/a:"}  # the failed one is tried again


def test_a_resumed_batch_must_have_been_made_the_same_way(tmp_path: Path) -> None:
    out = tmp_path / "out"
    Store(out).open(MANIFEST_A, resume=False)
    other = dict(MANIFEST_A, reference={"plant_sha256": "bb"})
    with pytest.raises(OutputError, match="another reference"):
        Store(out).open(other, resume=True)
    with pytest.raises(OutputError, match="another options"):
        Store(out).open(dict(MANIFEST_A, options={"alpha": 0.01}), resume=True)
    assert json.loads((out / MANIFEST).read_text()) == MANIFEST_A


def test_the_output_directory_rules(tmp_path: Path) -> None:
    assert check_out_dir(tmp_path / "new", resume=False, force=False) is False
    (tmp_path / "empty").mkdir()
    assert check_out_dir(tmp_path / "empty", resume=True, force=False) is False
    with pytest.raises(OutputError, match="does not exist"):
        check_out_dir(tmp_path / "missing" / "out", resume=False, force=False)
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="not a directory"):
        check_out_dir(tmp_path / "file", resume=False, force=False)
    others = tmp_path / "others"
    others.mkdir()
    (others / "thesis.tex").write_text("x")
    (others / RESULTS).write_bytes(b"")
    for resume, force in ((False, False), (True, False), (False, True)):
        with pytest.raises(OutputError, match="holds other things"):
            check_out_dir(others, resume=resume, force=force)
    ours = tmp_path / "ours"
    store = Store(ours)
    store.open(MANIFEST_A, resume=False)
    store.add(_row(1))
    store.close()
    with pytest.raises(OutputError, match="--resume adds"):
        check_out_dir(ours, resume=False, force=False)
    assert check_out_dir(ours, resume=True, force=False) is True
    assert check_out_dir(ours, resume=False, force=True) is False
    Store(ours).open(MANIFEST_A, resume=False)  # --force: our files go, the batch restarts
    assert sorted(p.name for p in ours.iterdir()) == [MANIFEST, PARTS]
