"""A short window of a long recording is read, not the recording: memory is bounded by the
window (checked with tracemalloc, never with a clock), and the model is the one a whole read
gives."""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from reliability_helpers import bag_of, known_data

import pmsm_sysid as ps
from pmsm_sysid.bagio import read_recording
from pmsm_sysid.bagio.read import READ_MARGIN
from pmsm_sysid.core.selection.identify import FitConfig, identify_recording
from pmsm_sysid.core.terms.model import Structure

WINDOW = {"ny": 2, "nu": 2, "terms": 5, "estimate": (1000, 2000), "validate": (3000, 4000)}

# the two long bags are written once: one test process runs this module (--dist loadgroup)
pytestmark = pytest.mark.xdist_group("bag_streaming")


def peak_bytes(fn: Callable[[], object]) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    root = tmp_path_factory.mktemp("long")
    u, y = known_data(120_000)
    return {n: bag_of(root / f"n{n}", u[:n], y[:n]) for n in (12_000, 120_000)}


@pytest.mark.slow
def test_memory_of_a_window_does_not_grow_with_the_recording(bags: dict[int, Path]) -> None:
    ps.identify(bags[12_000], **WINDOW)  # imports and caches outside the measurement
    small = peak_bytes(lambda: ps.identify(bags[12_000], **WINDOW))
    large = peak_bytes(lambda: ps.identify(bags[120_000], **WINDOW))
    # reading the 108 000 extra samples whole would take > 8 MB more (3 streams x 16 bytes
    # while reading, 4 aligned float64 signals after): 10x the recording, the same memory
    assert large < small + 1.5e6, (small, large)
    whole = peak_bytes(lambda: read_recording(bags[120_000]))
    assert whole > large - small + 6e6  # the whole read does cost that (the test can fail)


def test_the_window_read_fits_the_model_of_the_whole_read(bags: dict[int, Path]) -> None:
    part = read_recording(bags[120_000], until_sample=4000)
    assert not part.complete  # stopped soon after the margin (checked every 256 messages)
    assert 4000 + READ_MARGIN <= len(part.recording) < 4000 + READ_MARGIN + 300
    whole = read_recording(bags[12_000]).recording
    assert np.array_equal(part.recording.t, whole.t[: len(part.recording)])
    # the cut is where every topic was read: a message one topic read past another's cut
    # is not an unaligned sample (the EMPS bag once warned "5119 samples aligned (thrust
    # 5120, ...)" for 24841 samples, read as a truncated bag)
    r = part.report
    assert r.n_unaligned == 0 and r.n_thrust == r.n_speed == r.n_position == r.n_aligned
    config = FitConfig(structure=Structure(ny=2, nu=2, degree=2, delay=1), n_terms=5)
    ref = identify_recording(whole, input="thrust", output="speed", config=config,
                             estimate=(1000, 2000), validate=(3000, 4000)).to_dict()
    got = ps.identify(bags[120_000], **WINDOW).to_dict()
    assert [t["name"] for t in got["terms"]] == [t["name"] for t in ref["terms"]]
    assert np.allclose([t["estimate"] for t in got["terms"]],
                       [t["estimate"] for t in ref["terms"]], rtol=1e-12, atol=0)
