"""Excitation summary and support judgement (core/identifiability) on signals of known spectra."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import max_len_seq

from pmsm_sysid.core.errors import DataError, InsufficientExcitationError
from pmsm_sysid.core.identifiability import (
    ExcitationSummary,
    excitation_summary,
    identifiability_block,
    judge,
)

FS = 500.0
K = np.arange(1000)


def _sine(f_hz: float, n: int = 1000, amp: float = 1.0) -> np.ndarray:
    return amp * np.sin(2 * np.pi * f_hz * np.arange(n) / FS + 0.3)


def test_pure_tone_is_tonal_with_its_frequency() -> None:
    s = excitation_summary(_sine(16.5) + 7.0, FS)  # the mean does not matter
    assert not s.broadband
    assert s.n_lines == 1
    assert s.tones_hz[0] == pytest.approx(16.5, abs=0.05)
    lo, hi = s.band_hz
    assert 14.0 < lo < 16.5 < hi < 19.0
    assert s.band_norm == pytest.approx((lo / FS, hi / FS))
    assert s.line_power_fraction > 0.99


def test_tone_with_small_noise_still_tonal() -> None:
    rng = np.random.default_rng(1)
    s = excitation_summary(_sine(11.5) + 0.05 * rng.standard_normal(1000), FS)
    assert not s.broadband and s.tones_hz[0] == pytest.approx(11.5, abs=0.05)


def test_two_tones() -> None:
    s = excitation_summary(_sine(11.5) + 0.5 * _sine(40.0), FS)
    assert not s.broadband and s.n_lines == 2
    assert sorted(s.tones_hz) == pytest.approx([11.5, 40.0], abs=0.05)


@pytest.mark.parametrize("kind", ["white", "prbs"])
def test_broadband_signals(kind: str) -> None:
    rng = np.random.default_rng(2)
    prbs = 2.0 * max_len_seq(12)[0][:4000] - 1.0
    u = rng.standard_normal(4000) if kind == "white" else prbs
    s = excitation_summary(u, FS)
    assert s.broadband
    assert s.band_hz[0] == 0.0 and s.band_hz[1] > 240.0


def test_lowpass_noise_band_edge() -> None:
    """Noise filtered to 50 Hz: 99% of its power lies below ~50 Hz (scipy filter = truth)."""
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng(3)
    u = sosfiltfilt(butter(8, 50.0, fs=FS, output="sos"), rng.standard_normal(20000))
    s = excitation_summary(u, FS)
    assert s.broadband
    assert s.band_hz[0] == 0.0
    assert 40.0 < s.band_hz[1] < 60.0


def test_judgement_under_tone_and_broadband() -> None:
    tonal = excitation_summary(_sine(16.5), FS)
    j = judge(15.25, tonal)  # the paper's H1 peak reading, 1.25 Hz from the tone
    assert not j.supported and "AR(2)" in j.note
    assert not judge(-16.5, tonal).supported
    out = judge(100.0, tonal)
    assert not out.supported and "outside" in out.note
    rng = np.random.default_rng(4)
    broad = excitation_summary(rng.standard_normal(2000), FS)
    assert judge(15.25, broad).supported
    assert judge(0.0, broad).supported
    assert judge(16.5, None).supported  # nothing to check against: said so in the note
    assert "not checked" in judge(16.5, None).note


def test_roundtrip_and_block() -> None:
    s = excitation_summary(_sine(16.5), FS)
    d = s.to_dict()
    assert ExcitationSummary.from_dict(d) == s
    block = identifiability_block(s)
    assert block["excitation"] == d and "tonal" in block["rests_on"]
    assert identifiability_block(None)["excitation"] is None
    with pytest.raises(DataError):
        ExcitationSummary.from_dict({"band_hz": [1.0]})


def test_bad_inputs() -> None:
    with pytest.raises(InsufficientExcitationError):
        excitation_summary(np.full(100, 3.0), FS)
    with pytest.raises(DataError):
        excitation_summary(np.array([1.0, np.nan] * 50), FS)
    with pytest.raises(DataError):
        excitation_summary(np.ones(10), FS)
    with pytest.raises(DataError):
        excitation_summary(_sine(10.0), 0.0)
