"""Excitation signals: spectra where claimed (scipy.signal.welch), determinism, amplitudes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import chirp, welch

from pmsm_sysid.core.errors import ExcitationError
from pmsm_sysid.core.physics.excitation import (
    DEFAULT_AMPLITUDE_N,
    EXCITATIONS,
    ExcitationSource,
    make_excitation,
)
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant, nominal_plant

FS = 500.0
REPO = Path(__file__).resolve().parents[1]


def psd(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return welch(u, fs=FS, nperseg=2000)  # 0.25 Hz resolution


def band_fraction(f: np.ndarray, p: np.ndarray, lo: float, hi: float) -> float:
    sel = (f >= lo) & (f <= hi)
    return float(p[sel].sum() / p.sum())


@pytest.mark.parametrize(("kind", "peak_hz"), [("paper-speed", 16.5), ("paper-position", 11.5)])
def test_paper_signals_put_their_energy_where_the_seed_says(kind: str, peak_hz: float) -> None:
    u = make_excitation(kind, 10000, FS)
    f, p = psd(u)
    assert f[np.argmax(p)] == pytest.approx(peak_hz, abs=0.25)
    assert f[np.argmax(p)] / FS == pytest.approx({16.5: 0.033, 11.5: 0.023}[peak_hz], abs=5e-4)
    assert band_fraction(f, p, peak_hz - 1, peak_hz + 1) > 0.97
    assert np.abs(u).max() == pytest.approx(DEFAULT_AMPLITUDE_N[kind] + (3.0 if kind ==
                                            "paper-position" else 0.0), rel=0.02)


def test_paper_position_has_its_slow_positioning_move() -> None:
    u = make_excitation("paper-position", 10000, FS)
    f, p = psd(u)
    assert band_fraction(f, p, 0.25, 0.75) > 0.002  # the 0.5 Hz, 3 N component
    assert p[np.argmin(np.abs(f - 0.5))] > 100 * np.median(p)


def test_paper_signals_fade_in() -> None:
    u = make_excitation("paper-speed", 1000, FS)
    assert u[0] == 0.0
    assert np.abs(u[:25]).max() < 0.1 * 50  # first 50 ms under 10 %
    assert np.abs(u[250:]).max() == pytest.approx(50.0, rel=1e-3)  # full after 0.5 s
    no_fade = make_excitation("paper-speed", 100, FS, fade_s=0.0)
    np.testing.assert_allclose(no_fade, 50 * np.sin(2 * np.pi * 16.5 * np.arange(100) / FS))


@pytest.mark.parametrize("phases", ["random", "schroeder"])
def test_multisine_flat_band_and_peak(phases: str) -> None:
    src = ExcitationSource("multisine", FS, seed=3, f_min_hz=2.0, f_max_hz=30.0, phases=phases)
    period = src.block(0, 2000)                      # period_s = 4 s
    np.testing.assert_array_equal(src.block(2000, 2000), period)
    spectrum = np.abs(np.fft.rfft(period))
    freqs = np.fft.rfftfreq(2000, 1 / FS)
    lines = (freqs >= 2.0) & (freqs <= 30.0)
    assert lines.sum() == 113
    np.testing.assert_allclose(spectrum[lines], spectrum[lines][0], rtol=1e-9)   # flat
    assert spectrum[~lines].max() < 1e-9 * spectrum[lines][0]                   # nothing else
    assert np.abs(period).max() == pytest.approx(30.0)
    f, p = psd(src.block(0, 20000))
    assert band_fraction(f, p, 1.5, 30.5) > 0.99
    if phases == "schroeder":  # low crest factor by design
        assert np.abs(period).max() / period.std() < 2.0


def test_chirp_matches_scipy_and_band() -> None:
    u = make_excitation("chirp", 5000, FS, f0_hz=2.0, f1_hz=50.0, period_s=10.0)
    t = np.arange(5000) / FS
    np.testing.assert_allclose(u, 30.0 * chirp(t, 2.0, 10.0, 50.0, method="linear"), atol=1e-9)
    log = make_excitation("chirp", 5000, FS, method="logarithmic", f0_hz=2.0, f1_hz=50.0)
    np.testing.assert_allclose(log, 30.0 * chirp(t, 2.0, 10.0, 50.0, method="logarithmic"),
                               atol=1e-8)
    f, p = psd(u)
    assert band_fraction(f, p, 1.5, 50.5) > 0.97


def test_prbs_is_a_maximum_length_sequence() -> None:
    order, hold, amp = 9, 4, 20.0
    u = make_excitation("prbs", 3 * 511 * hold, FS, seed=7, order=order, hold=hold)
    assert set(np.unique(u)) == {-amp, amp}
    one = u[:511 * hold]
    np.testing.assert_array_equal(u[511 * hold:2 * 511 * hold], one)
    bits = one[::hold] > 0
    np.testing.assert_array_equal(np.repeat(bits, hold), one > 0)
    assert bits.sum() == 256  # an m-sequence has 2^(n-1) ones per period
    s = np.where(bits, 1.0, -1.0)
    circ = np.array([s @ np.roll(s, lag) for lag in range(1, 511)])
    np.testing.assert_array_equal(circ, -1.0)  # two-valued autocorrelation
    f, p = psd(make_excitation("prbs", 40000, FS, seed=7, hold=5))
    null = p[np.argmin(np.abs(f - FS / 5))]       # sinc^2 null at fs/hold = 100 Hz
    assert null < 1e-2 * p[(f > 1) & (f < 10)].mean()


def test_aprbs_levels_and_holds() -> None:
    u = make_excitation("aprbs", 10000, FS, seed=2, min_hold=10, max_hold=60)
    assert np.abs(u).max() <= 20.0
    change = np.flatnonzero(np.diff(u[:10000]) != 0) + 1
    runs = np.diff(change)
    period_end = 20.0 * FS  # samples; the last run of a period may be cut
    inside = runs[change[1:] < period_end - 60]
    assert inside.min() >= 10 and inside.max() <= 60
    assert len(np.unique(u)) > 100            # many amplitude levels
    assert np.std(u) > 8.0


def test_broadband_is_flat_to_near_nyquist_and_persistently_exciting() -> None:
    """The run's default: every 0.25 Hz line in 0.5-240 Hz at one level, 60 N peak, and of
    persistent-excitation order >= 40 over 40 input lags (the speed structure's)."""
    from pmsm_sysid.core.selection.datacheck import describe_fit_data
    from pmsm_sysid.core.terms.model import Structure

    u = make_excitation("broadband", 2000, FS, seed=2)  # one 4 s period
    spec = np.abs(np.fft.rfft(u))
    f = np.fft.rfftfreq(len(u), 1 / FS)
    lines = spec > 1e-6 * spec.max()
    assert np.allclose(f[lines][[0, -1]], [0.5, 240.0])
    assert lines.sum() == 959 and np.ptp(spec[lines]) < 1e-9 * spec.max()
    assert np.max(np.abs(u)) == pytest.approx(60.0)
    check = describe_fit_data(u, Structure(ny=30, nu=40, degree=2, delay=1))
    assert check.pe_order == 40 and not check.warnings


@pytest.mark.parametrize("kind", EXCITATIONS)
def test_blocks_concatenate_and_seed_determines(kind: str) -> None:
    src = ExcitationSource(kind, FS, seed=11)
    whole = src.block(0, 3000)
    parts = np.concatenate([src.block(0, 4), src.block(4, 6), src.block(10, 2990)])
    np.testing.assert_array_equal(whole, parts)
    np.testing.assert_array_equal(ExcitationSource(kind, FS, seed=11).block(0, 3000), whole)
    np.testing.assert_array_equal(make_excitation(kind, 3000, FS, seed=11), whole)
    assert src.value(1234) == whole[1234]
    other = ExcitationSource(kind, FS, seed=12).block(0, 3000)
    if kind in ("multisine", "prbs", "aprbs", "broadband"):
        assert not np.array_equal(other, whole)
    else:  # deterministic signals without random parameters
        np.testing.assert_array_equal(other, whole)
    assert np.isfinite(whole).all() and src.block(5, 0).shape == (0,)


@settings(max_examples=40, deadline=None)
@given(kind=st.sampled_from(EXCITATIONS), k0=st.integers(0, 50000), cut=st.integers(0, 300),
       n=st.integers(0, 300))
def test_any_split_is_consistent(kind: str, k0: int, cut: int, n: int) -> None:
    src = ExcitationSource(kind, FS, seed=1)
    cut = min(cut, n)
    np.testing.assert_array_equal(src.block(k0, n),
                                  np.concatenate([src.block(k0, cut), src.block(k0 + cut,
                                                                                n - cut)]))


def test_amplitude_scales() -> None:
    for kind in EXCITATIONS:
        a = make_excitation(kind, 2000, FS, seed=1)
        b = make_excitation(kind, 2000, FS, seed=1, amplitude_n=2 * DEFAULT_AMPLITUDE_N[kind])
        if kind == "paper-position":  # the slow move keeps its own amplitude option
            b = make_excitation(kind, 2000, FS, amplitude_n=80.0, slow_amplitude_n=6.0)
        np.testing.assert_allclose(b, 2 * a, rtol=1e-12, atol=1e-12)


def test_default_amplitudes_suit_the_83_w_motor() -> None:
    """paper-speed: speed amplitude of tens of cm/s (seed Fig. 2); paper-position on the
    position plant: cm-scale travel (seed Fig. 7); every signal within rated 1 m/s."""
    nominal = nominal_plant()
    rec = simulate(nominal, make_excitation("paper-speed", 4000, FS))
    amp = np.abs(rec.speed[1000:2000]).max()
    assert 0.1 < amp < 0.4
    pos = simulate(load_plant(REPO / "plants" / "position.yaml"),
                   make_excitation("paper-position", 4000, FS), seed=0).position[1000:2000]
    assert 0.02 < pos.max() - pos.min() < 0.2
    assert abs(pos.mean()) < 0.02
    for kind in EXCITATIONS:
        v = simulate(nominal, make_excitation(kind, 5000, FS, seed=0)).speed
        assert np.abs(v).max() < 1.0, kind


@pytest.mark.parametrize(("kwargs", "fragment"), [
    ({"kind": "sine"}, "unknown excitation 'sine'; valid: paper-speed, paper-position"),
    ({"kind": "chirp", "f9_hz": 3}, "unknown option(s) f9_hz; valid: f0_hz"),
    ({"kind": "multisine", "phases": "zero"}, "phases must be one of random, schroeder"),
    ({"kind": "multisine", "f_min_hz": 300.0, "f_max_hz": 400.0}, "no frequency line"),
    ({"kind": "chirp", "f1_hz": 300.0}, "below Nyquist"),
    ({"kind": "paper-speed", "frequency_hz": -1.0}, "frequency_hz must be positive"),
    ({"kind": "paper-speed", "frequency_hz": 260.0}, "below Nyquist"),
    ({"kind": "prbs", "order": 30}, "order must be an integer in 2..18"),
    ({"kind": "aprbs", "min_hold": 50, "max_hold": 10}, "min_hold <= max_hold"),
    ({"kind": "prbs", "amplitude_n": -1.0}, "amplitude must be a finite number >= 0"),
    ({"kind": "prbs", "amplitude_n": float("nan")}, "amplitude must be a finite number"),
    ({"kind": "chirp", "period_s": 0.001}, "shorter than 4 samples"),
    ({"kind": "chirp", "period_s": "long"}, "period_s must be a finite number"),
])
def test_bad_requests_give_one_line(kwargs: dict[str, object], fragment: str) -> None:
    with pytest.raises(ExcitationError) as info:
        ExcitationSource(sample_rate_hz=FS, **kwargs)  # type: ignore[arg-type]
    assert fragment in str(info.value)
    assert "\n" not in str(info.value)
    with pytest.raises(ExcitationError, match="k0 >= 0"):
        ExcitationSource("prbs", FS).block(-1, 3)
