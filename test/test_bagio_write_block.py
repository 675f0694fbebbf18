"""Recordings appended to an MCAP bag a block at a time (bagio.mcap_block) give the files
``rosbags``' writer makes message by message: the same bytes, chunks split at the same
records, the same message indexes, times, counts and metadata."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

import pmsm_sysid.bagio.write as bag_write
from pmsm_sysid.bagio import read_recording, write_recording
from pmsm_sysid.bagio.mcap_block import CHUNK_BYTES
from pmsm_sysid.bagio.write import recording_writer
from pmsm_sysid.core.recording.signals import Recording, derive_speed


def _rec(n: int, derived: bool = False, seed: int = 3, odd: bool = False) -> Recording:
    rng = np.random.default_rng(seed)
    t = 12.5 + np.arange(n) / 500.0
    x = np.cumsum(rng.normal(size=n)) * 1e-4
    v = derive_speed(t, x) if derived else rng.normal(size=n)
    thrust = rng.normal(size=n) * 10
    if odd:  # written as they are, bit for bit
        thrust[: min(n, 3)] = [-0.0, np.nan, -np.inf][:n]
    return Recording(t=t, thrust=thrust, speed=v, position=x, sample_rate_hz=500.0,
                     speed_derived=derived, source="test", meta={"note": "block"})


def _files(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


def _both(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, write: object) -> tuple[
        dict[str, bytes], dict[str, bytes]]:
    """The files of the bag written a block at a time and message by message (bags of the
    same name: the name is in the file's name and metadata)."""
    write(tmp_path / "block" / "bag")  # type: ignore[operator]
    with monkeypatch.context() as m:
        m.setattr(bag_write, "block_writer", lambda writer: None)  # message by message
        write(tmp_path / "each" / "bag")  # type: ignore[operator]
    return _files(tmp_path / "block" / "bag"), _files(tmp_path / "each" / "bag")


@pytest.mark.parametrize("n,derived,extra,odd", [
    (1, False, 0, True), (5000, False, 0, False), (5000, True, 0, False),
    (3000, False, 2, True),
    # several chunks, a chunk split inside a sample's records, and two blocks of samples
    (bag_write.WRITE_BLOCK + 1234, False, 1, False),
])
def test_a_recording_is_the_same_file_as_written_message_by_message(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, n: int, derived: bool,
        extra: int, odd: bool) -> None:
    rec = _rec(n, derived, odd=odd)
    points = {f"ref{k}": np.sin(np.arange(n) * (k + 1) * 1e-3) for k in range(extra)}
    block, each = _both(tmp_path, monkeypatch,
                        lambda p: write_recording(p, rec, extra_points=points))
    assert block == each
    if n > CHUNK_BYTES // 100:  # the long case does span chunks and blocks
        with AnyReader([tmp_path / "block" / "bag"]) as reader:
            assert len(reader.readers[0].storage.storages[0].chunks) >= 5  # type: ignore
    if not odd:  # a reader refuses the non-finite thrust
        got = read_recording(tmp_path / "block" / "bag").recording
        assert np.array_equal(got.thrust, rec.thrust)
        assert np.array_equal(got.position, rec.position)
        assert np.allclose(got.t, rec.t, rtol=0, atol=1e-9)  # stamps in whole ns


def test_blocks_appended_one_after_another_are_the_same_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A bag written span by span (as a long simulation is): uneven spans, chunk
    boundaries falling anywhere in them."""
    whole = _rec(40_000)
    cuts = [0, 1, 3, 7, 9000, 9001, 25_000, 40_000]

    def write(path: Path) -> None:
        with recording_writer(path, whole) as out:
            for a, b in itertools.pairwise(cuts):
                out.write(whole.window(a, b))

    block, each = _both(tmp_path, monkeypatch, write)
    assert block == each


def test_sqlite3_bags_are_written_message_by_message(tmp_path: Path) -> None:
    rec = _rec(700)
    write_recording(tmp_path / "lite", rec, storage="sqlite3")
    got = read_recording(tmp_path / "lite").recording
    assert np.array_equal(got.speed, rec.speed)
    assert bag_write.block_writer(object()) is None
