"""The MCAP chunks read directly give what ``rosbags`` gives: the same messages, in the same
order (log time, then chunk, then record), for every window and topic choice, on bags whose
chunks overlap in time, compressed or not; a damaged chunk gets ``rosbags``' own error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

from pmsm_sysid import topics as tp
from pmsm_sysid.bagio import mcap_messages, read_recording
from pmsm_sysid.bagio.cdr import encode_stamped
from pmsm_sysid.bagio.common import DEFAULT_QOS, connection_args, open_reader
from pmsm_sysid.core.errors import BagError

N = 12_000  # per topic: 36 000 records of ~100 bytes, several 1 MB chunks
TOPICS = {"/m/thrust": tp.THRUST_TYPE, "/m/speed": tp.SPEED_TYPE,
          "/m/position": tp.POSITION_TYPE}
# One test process builds the two bags (module fixture) and reads them in every test: under
# ``--dist loadgroup`` the tests were spread over both processes and each built both bags.
pytestmark = pytest.mark.xdist_group("bagio_mcap_messages")


def _bag(path: Path, compressed: bool) -> Path:
    """Three input topics whose log times jitter, repeat and run back across chunks."""
    rng = np.random.default_rng(5)
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if compressed:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conns = []
        for topic, msgtype in TOPICS.items():
            msgdef, digest = connection_args(msgtype)
            conns.append((writer.add_connection(topic, msgtype, msgdef=msgdef, rihs01=digest,
                                                offered_qos_profiles=[DEFAULT_QOS]), msgtype))
        for k in range(N):
            stamp = 10**9 + k * 2_000_000
            for conn, msgtype in conns:
                log = stamp + int(rng.integers(-3, 4)) * 1_000_000  # ties and reorderings
                if k % 4000 == 3999:
                    log -= 5 * 10**9  # logged late: overlaps the chunks written before
                writer.write(conn, log, encode_stamped(msgtype, stamp, "pmsm",
                                                       float(rng.standard_normal())))
    return path


@pytest.fixture(scope="module", params=[False, True], ids=["plain", "zstd"])
def bag(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _bag(tmp_path_factory.mktemp("mcap") / "bag", request.param)


WINDOWS = [(None, None), (None, 10**9 + 5 * 10**9), (10**9 + 7 * 10**9, None),
           (10**9 + 3 * 10**9, 10**9 + 21 * 10**9), (0, 1), (10**9 + 4_000_000, 10**9 + 4_000_001)]


@pytest.mark.parametrize("window", WINDOWS)
def test_the_same_messages_in_the_same_order_as_rosbags(bag: Path,
                                                        window: tuple[int, int]) -> None:
    with open_reader(bag) as reader:
        assert len(reader.storage.storages[0].chunks) >= 3  # the merge is exercised
        for conns in (list(reader.connections), list(reader.connections)[::2],
                      [c for c in reader.connections if c.topic == "/m/position"]):
            want = list(reader.messages(connections=conns, start=window[0], stop=window[1]))
            got = list(mcap_messages.messages(reader, conns, *window))
            assert [(c.id, t) for c, t, _ in got] == [(c.id, t) for c, t, _ in want]
            assert all(a[2] == b[2] and type(a[2]) is type(b[2])
                       for a, b in zip(got, want, strict=True))


def test_the_direct_read_is_the_one_taken(bag: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A test that cannot pass through rosbags' reader: the direct read is really used."""
    with open_reader(bag) as reader:
        monkeypatch.setattr(reader, "messages", None)
        assert len(list(mcap_messages.messages(reader, list(reader.connections)))) == 3 * N


def test_a_bag_read_directly_aligns_as_through_rosbags(bag: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    fast = read_recording(bag)
    monkeypatch.setattr(mcap_messages, "_indexed", lambda *a: None)  # rosbags alone
    slow = read_recording(bag)
    for name in ("t", "thrust", "speed", "position"):
        assert np.array_equal(getattr(fast.recording, name), getattr(slow.recording, name))
    assert fast.report == slow.report and len(fast.recording) == N


def _damage(bag: Path, tmp: Path) -> Path:
    """A copy of the bag with its second chunk's first bytes overwritten: the length of its
    first record (uncompressed) or the compressed frame's header."""
    out = tmp / "damaged"
    out.mkdir()
    (out / "metadata.yaml").write_text((bag / "metadata.yaml").read_text())
    data = bytearray((bag / "bag.mcap").read_bytes())
    with open_reader(bag) as reader:
        chunk = sorted(reader.storage.storages[0].chunks, key=lambda c: c.chunk_start_offset)[1]
    at = chunk.chunk_start_offset + 9 + 40 + len(chunk.compression) + 1
    data[at:at + 8] = b"\xff" * 8
    (out / "damaged.mcap").write_bytes(bytes(data))
    meta = (out / "metadata.yaml").read_text().replace("bag.mcap", "damaged.mcap")
    (out / "metadata.yaml").write_text(meta)
    return out


def test_a_damaged_chunk_gets_the_error_rosbags_gives(bag: Path, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    damaged = _damage(bag, tmp_path)
    with pytest.raises(BagError) as fast:
        read_recording(damaged)
    with open_reader(damaged) as reader:  # the messages before the damage come first
        conns = list(reader.connections)
        given: list[tuple[int, int]] = []
        with pytest.raises(Exception) as direct:
            for c, t, _ in mcap_messages.messages(reader, conns):
                given.append((c.id, t))
        before: list[tuple[int, int]] = []
        with pytest.raises(Exception) as through:
            for c, t, _ in reader.messages(connections=conns):
                before.append((c.id, t))
    assert given == before and len(given) > 0
    assert str(direct.value) == str(through.value)
    monkeypatch.setattr(mcap_messages, "_indexed", lambda *a: None)
    with pytest.raises(BagError) as slow:
        read_recording(damaged)
    assert str(fast.value) == str(slow.value)
    assert "corrupt or truncated" in str(fast.value)
