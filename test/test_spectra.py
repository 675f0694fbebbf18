"""Welch spectra and peak finding without scipy.signal (core/recording/spectra.py): the
same numbers as SciPy's (the peer), and a live worker that fits windows and analyses their
models imports neither scipy.signal nor scipy.stats (what that module is for)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from pmsm_sysid.core.recording.spectra import find_peaks, hann, welch


def _signals(seed: int, count: int) -> list[np.ndarray]:
    """Random walks, coarse noise with flat tops (plateaus of every length), flat or high
    ends, and the shortest signals, from 0 to 300 samples."""
    rng = np.random.default_rng(seed)
    out = [np.zeros(0), np.ones(1), np.array([0.0, 1.0]), np.array([0.0, 1.0, 0.0]),
           np.array([0.0, 1.0, 1.0, 0.0]), np.array([1.0, 1.0, 0.0, 1.0, 1.0])]
    for k in range(count):
        n = int(rng.integers(0, 300))
        x = np.cumsum(rng.standard_normal(n)) if k % 2 else np.round(rng.standard_normal(n))
        if k % 5 == 0 and n > 3:  # a flat start, or a flat end above everything
            x[:n // 4] = x[n // 4]
        if k % 7 == 0 and n > 3:
            x[-(n // 5 + 1):] = x.max() + 1.0
        out.append(x)
    return out


@pytest.mark.parametrize("prominence", [None, 0.0, 0.5, 2.0])
def test_find_peaks_is_scipys_bit_for_bit(prominence: float | None) -> None:
    peer_prominence = (None, None) if prominence is None else prominence
    for x in _signals(seed=3, count=400):
        want, props = signal.find_peaks(x, prominence=peer_prominence)
        got, prom = find_peaks(x, prominence=prominence)
        assert np.array_equal(got, want), x
        assert np.array_equal(prom, props["prominences"]), x


def test_a_flat_top_peaks_in_its_middle_and_an_edge_never_peaks() -> None:
    x = np.array([3.0, 0.0, 2.0, 2.0, 2.0, 2.0, 1.0, 5.0, 5.0, 0.0, 4.0])
    peaks, prom = find_peaks(x)
    assert peaks.tolist() == [3, 7]  # (2 + 5) // 2 and (7 + 8) // 2; not 0, not 10
    # 2 above the higher base (1, before the 5 on its right); 5 above 0 (nothing higher)
    assert prom.tolist() == [2.0 - 1.0, 5.0 - 0.0]


def test_welch_is_scipys_to_rounding() -> None:
    rng = np.random.default_rng(5)
    assert np.array_equal(hann(128), signal.get_window("hann", 128))
    for n, nperseg in ((1000, 128), (999, 128), (1000, 512), (128, 128), (77, 77), (5000, 512),
                       (300, 7), (2, 2)):
        for detrend in (True, False):
            x = rng.standard_normal(n) * rng.uniform(0.1, 100.0) + rng.uniform(-5.0, 5.0)
            f0, p0 = signal.welch(x, fs=500.0, nperseg=nperseg,
                                  detrend="constant" if detrend else False)
            f, p = welch(x, 500.0, nperseg=nperseg, detrend=detrend)
            assert np.array_equal(f, f0)
            assert np.max(np.abs(p - p0)) <= 1e-12 * np.max(p0), (n, nperseg, detrend)


def test_welch_of_a_tone_and_of_white_noise() -> None:
    """Independent truths: a tone on a bin puts its power (A^2 / 2) in its bin and the
    window's neighbours; unit white noise has a flat one-sided density of 2 / fs."""
    fs, n = 500.0, 128
    t = np.arange(64 * n) / fs
    f, p = welch(3.0 * np.sin(2 * np.pi * 50.78125 * t), fs, nperseg=n)  # bin 13
    df = f[1] - f[0]
    assert int(np.argmax(p)) == 13
    assert np.sum(p[11:16]) * df == pytest.approx(3.0**2 / 2, rel=1e-9)
    noise = np.random.default_rng(1).standard_normal(400 * n)
    _, q = welch(noise, fs, nperseg=n)
    assert np.median(q[1:-1]) == pytest.approx(2.0 / fs, rel=0.05)


@pytest.mark.parametrize("nperseg", [1, 11])
def test_welch_refuses_a_segment_it_cannot_take(nperseg: int) -> None:
    with pytest.raises(ValueError, match="nperseg"):
        welch(np.zeros(10), nperseg=nperseg)


def test_a_live_worker_fits_and_analyses_without_scipy_signal_or_stats() -> None:
    """The identifier's and GFRF node's work in a worker process (forked from the fork
    server with what it preloads): the default motor's windows, fitted until models and
    cross-validations come and each model analysed; the work never imported scipy.signal
    or scipy.stats (nor does the server's own preload: test_api's import test)."""
    from worker_probe import FitAndAnalyse

    from pmsm_sysid.core.online.livesim import simulated_windows
    from pmsm_sysid.core.online.tracker import tracker_config
    from pmsm_sysid.core.online.workerproc import ProcessWorker
    from pmsm_sysid.core.physics.plant import load_plant
    from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS

    params = dict(IDENTIFIER_DEFAULTS)
    cfg = tracker_config(params)
    plant = load_plant("drive")
    seen = {"models": 0, "validations": 0, "analyses": 0}
    with ProcessWorker(FitAndAnalyse, (params,)) as worker:
        for w in simulated_windows(plant, "aprbs", 12 * cfg.hop + cfg.window,
                                   window=cfg.window, hop=cfg.hop, history=cfg.history):
            got = worker(w)
            for key in seen:
                seen[key] += got[key]
            assert got["loaded"] == [], got
    assert seen["models"] >= 2 and seen["validations"] >= 1, seen
    assert seen["analyses"] == seen["models"]
