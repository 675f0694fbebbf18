"""The input topics read a chunk at a time into arrays (bagio.mcap_arrays) give what the
message-by-message read gives: the same samples in the same order, the same early stop of a
partial read, the same report; on bags with ties and reorderings inside chunks, windows of
log time and of stamps; bags whose chunks overlap in time are read message by message."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin

import pmsm_sysid.bagio.mcap_arrays as mcap_arrays
from pmsm_sysid import topics as tp
from pmsm_sysid.bagio import mcap_messages, read_recording, write_recording
from pmsm_sysid.bagio.cdr import encode_stamped
from pmsm_sysid.bagio.common import DEFAULT_QOS, connection_args, open_reader, typestore
from pmsm_sysid.core.recording.signals import Recording, derive_speed

String = typestore().types["std_msgs/msg/String"]
N = 12_000
TOPICS = {"/pmsm/thrust": tp.THRUST_TYPE, "/pmsm/speed": tp.SPEED_TYPE,
          "/pmsm/position": tp.POSITION_TYPE}
pytestmark = pytest.mark.xdist_group("bagio_read_arrays")


def _bag(path: Path, overlap: bool) -> Path:
    """Log times in 10 ms buckets, backwards inside each (ties across topics, reordered
    samples), a chunk closed every 2000 samples; ``overlap``: a sample logged 5 s late
    every 4000, so chunks overlap in time. A text topic of messages of other sizes now and
    then (as a run's models are) breaks the chunks' cycle of record sizes, and so does a
    sample written in another order of topics."""
    rng = np.random.default_rng(9)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = []
        for topic, msgtype in TOPICS.items():
            msgdef, digest = connection_args(msgtype)
            conns.append((writer.add_connection(topic, msgtype, msgdef=msgdef, rihs01=digest,
                                                offered_qos_profiles=[DEFAULT_QOS]), msgtype))
        text = writer.add_connection("/pmsm/model", "std_msgs/msg/String",
                                     typestore=typestore())
        for k in range(N):
            if k % 700 == 350 and k < 6000:  # in the first three chunks
                data = typestore().serialize_cdr(String(data="m" * (k % 97)),
                                                 "std_msgs/msg/String")
                writer.write(text, 10**9 + (k // 5) * 10_000_000, data)
            stamp = 10**9 + k * 2_000_000
            log = 10**9 + (k // 5) * 10_000_000 + (4 - k % 5) * 1_000_000
            if overlap and k % 4000 == 3999:
                log -= 5 * 10**9
            # now and then a sample's topics in another order: the same bytes in all, in
            # records of other sizes where the chunk's cycle predicts them
            swap = k % 997 == 500 and 6000 <= k < 10_000  # the next two; the last is plain
            for conn, msgtype in conns[::-1] if swap else conns:
                writer.write(conn, log, encode_stamped(msgtype, stamp, "pmsm",
                                                       float(rng.standard_normal())))
            if k % 2000 == 1999:
                writer.storage.close_chunk()  # type: ignore[union-attr]
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("arrays")
    rng = np.random.default_rng(4)
    t = np.arange(7000) / 500.0
    x = np.cumsum(rng.normal(size=7000)) * 1e-4
    derived = Recording(t=t, thrust=rng.normal(size=7000), speed=derive_speed(t, x),
                        position=x, sample_rate_hz=500.0, speed_derived=True)
    write_recording(root / "derived", derived)
    return {"in_order": _bag(root / "in_order", False),
            "overlap": _bag(root / "overlap", True), "derived": root / "derived"}


def _read(path: Path, arrays: bool, monkeypatch: pytest.MonkeyPatch, **kw: Any) -> Any:
    with monkeypatch.context() as m:
        if arrays:  # and nothing else: the message-by-message read would fail
            m.setattr(mcap_messages, "messages", None)
        else:
            m.setattr(mcap_arrays, "read_stamped", lambda *a, **k: None)
        return read_recording(path, **kw)


SECOND = 10**9
READS: list[dict[str, Any]] = [
    {}, {"until_sample": 100}, {"until_sample": 1800}, {"until_sample": 5000},
    {"until_sample": 11_500}, {"until_sample": 20_000},
    {"window": (None, None, 3 * SECOND, 9 * SECOND)},
    {"window": (5 * SECOND, 17 * SECOND, 6 * SECOND, 16 * SECOND)},
    {"window": (5 * SECOND, None, 0, 2**62), "until_sample": 2000},
]


@pytest.mark.parametrize("kw", READS, ids=[str(sorted(k)) + str(i) for i, k in enumerate(READS)])
@pytest.mark.parametrize("name", ["in_order", "derived"])
def test_a_chunk_at_a_time_gives_the_message_by_message_read(
        bags: dict[str, Path], monkeypatch: pytest.MonkeyPatch, name: str,
        kw: dict[str, Any]) -> None:
    if name == "derived" and "window" in kw:
        kw = {**kw, "window": None}
    fast = _read(bags[name], True, monkeypatch, **kw)
    slow = _read(bags[name], False, monkeypatch, **kw)
    for field in ("t", "thrust", "speed", "position"):
        assert np.array_equal(getattr(fast.recording, field), getattr(slow.recording, field))
    assert fast.report == slow.report and fast.complete == slow.complete
    if kw.get("until_sample") in (100, 1800, 5000):
        assert not fast.complete  # the early stop is exercised


def test_chunks_that_overlap_in_time_are_read_message_by_message(
        bags: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    with open_reader(bags["overlap"]) as reader:
        conns = [c for c in reader.connections if c.topic in TOPICS]
        assert mcap_arrays.read_stamped(reader, conns, {c.id: 0 for c in conns}, 1,
                                        (None, None, 0, 2**62), None, 0) is None
    with open_reader(bags["in_order"]) as reader:
        conns = [c for c in reader.connections if c.topic in TOPICS]
        assert len(reader.storage.storages[0].chunks) >= 6  # type: ignore[attr-defined]
        got = mcap_arrays.read_stamped(reader, conns, {c.id: 0 for c in conns}, 1,
                                       (None, None, 0, 2**62), None, 0)
        assert got is not None and len(got[0][0][0]) == 3 * N
    fast = _read(bags["overlap"], False, monkeypatch)
    assert len(fast.recording) == N


def test_both_ways_of_walking_a_chunk_are_taken(bags: dict[str, Path],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The in-order bag has chunks whose records follow one cycle of sizes (predicted and
    checked at once), and chunks where another record or order breaks it (walked one by
    one): the comparisons above cover both."""
    outcomes: list[bool] = []
    predicted = mcap_arrays._predicted

    def counted(*args: Any) -> Any:
        got = predicted(*args)
        outcomes.append(got is not None)
        return got

    monkeypatch.setattr(mcap_arrays, "_predicted", counted)
    read_recording(bags["in_order"])
    assert True in outcomes and False in outcomes, outcomes
