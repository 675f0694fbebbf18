"""Checks before a fit: bad data are refused with one clear error, weak excitation flagged."""

from __future__ import annotations

import numpy as np
import pytest
from narx_systems import LINEAR, simulate, white_input

from pmsm_sysid.core.errors import DataError, InsufficientExcitationError
from pmsm_sysid.core.selection.datacheck import check_fit_data, pe_order
from pmsm_sysid.core.selection.identify import FitConfig, fit_narx
from pmsm_sysid.core.terms.model import Structure

K = np.arange(1200)
ST = Structure(ny=4, nu=12, degree=2)


def test_non_finite_samples_name_the_signal_and_index() -> None:
    u, y = white_input(1200), white_input(1200, seed=2)
    y[321] = np.inf
    with pytest.raises(DataError, match=r"'speed' has 1 non-finite samples \(first at index 321\)"):
        check_fit_data(y, u, ST, 5, input_name="thrust", output_name="speed")


def test_too_short_names_the_need() -> None:
    u = white_input(30)
    with pytest.raises(DataError, match="need at least 42"):
        check_fit_data(u, u, ST, 15)  # max lag 12 + 2 x 15 parameters


def test_constant_input_or_output_is_insufficient_excitation() -> None:
    with pytest.raises(InsufficientExcitationError, match="constant"):
        check_fit_data(white_input(500), np.full(500, 3.0), ST, 5)
    with pytest.raises(InsufficientExcitationError, match="constant"):
        check_fit_data(np.ones(500), white_input(500), ST, 5)


@pytest.mark.parametrize("signal,order", [
    (np.sin(2 * np.pi * 0.033 * K), 2),  # one tone: persistently exciting of order 2
    (2.0 + np.sin(2 * np.pi * 0.11 * K), 3),  # plus a d.c. level
    (np.sin(2 * np.pi * 0.033 * K) + np.sin(2 * np.pi * 0.11 * K), 4),  # two tones
    (np.sin(2 * np.pi * 0.033 * K) + 0.03 * white_input(1200), 2),  # ~30 dB down noise
    (white_input(1200), 12),  # white: every lag
])
def test_persistent_excitation_order(signal: np.ndarray, order: int) -> None:
    assert pe_order(signal, ST) == order
    check = check_fit_data(white_input(1200, seed=4), signal, ST, 5, input_name="thrust")
    assert check.pe_order == order
    assert check.pe_sufficient == (order >= 12)
    assert bool(check.warnings) == (order < 12)


def test_single_tone_protocol_fits_and_is_flagged_never_nan() -> None:
    """The paper's protocol (one tone, nu = 40 input lags): rank-deficient candidates are
    skipped, the fit is finite, the result says why input terms are not unique."""
    u = 30.0 * np.sin(2 * np.pi * 0.033 * np.arange(1100))
    y = simulate(LINEAR, u / 30.0, noise_std=1e-3)
    f = fit_narx(y, u, FitConfig(structure=Structure(ny=30, nu=40, degree=2), n_terms=15))
    assert np.all(np.isfinite(f.model.estimates)) and np.all(np.isfinite(f.model.std))
    assert f.data_check is not None and f.data_check.pe_order == 2
    assert "order 2" in f.data_check.warnings[0]
    assert sum(t.u_lags != () for t in f.model.terms) >= 1
