"""The fit's zero-phase filter and filter designs give what SciPy's give, bit for bit and
in the same memory layout (a reduction downstream sums in the order it did), and the fit's
data built with them are those built with SciPy's own calls."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import signal

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.plantfit import kinematics, zerophase
from pmsm_sysid.core.plantfit.feedback import feedback_z
from pmsm_sysid.core.plantfit.kinematics import equation_data, kinematic_mode
from pmsm_sysid.core.plantfit.reading import noise_gap

DESIGNS = [(4, 40.0, 500.0, "lowpass"), (4, 150.0, 500.0, "highpass"),
           (4, 25.0, 1000.0, "lowpass"), (2, 5.0, 500.0, "lowpass"),
           (3, 60.0, 500.0, "lowpass")]  # an odd order: a first-order section


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.strides == b.strides and np.array_equal(a, b)


@pytest.mark.parametrize("design", DESIGNS)
def test_the_filter_is_scipys(design: tuple[int, float, float, str]) -> None:
    order, fc, fs, band = design
    sos = zerophase.butter_sos(order, fc, fs, band)  # type: ignore[arg-type]
    assert np.array_equal(sos, signal.butter(order, fc, btype=band, fs=fs, output="sos"))
    rng = np.random.default_rng(order)
    shapes = [((5000,), -1), ((5000,), 0), ((300, 7), 0), ((7, 300), -1), ((7, 300), 1),
              ((40,), 0), ((4000, 32), 0), ((4000, 1), 0), ((1, 900), -1)]
    for shape, axis in shapes:
        for x in (rng.standard_normal(shape), rng.standard_normal(shape[::-1]).T,
                  rng.standard_normal((2 * shape[0], *shape[1:]))[::2]):
            if x.shape[axis] <= 3 * (2 * len(sos) + 1):
                continue
            want = signal.sosfiltfilt(sos, x, axis=axis)
            assert _same(zerophase.sosfiltfilt(sos, x, axis=axis), want), (shape, axis)


def test_what_the_fast_path_does_not_take_goes_to_scipy() -> None:
    sos = zerophase.butter_sos(4, 40.0, 500.0)
    with pytest.raises(ValueError) as new:
        zerophase.sosfiltfilt(sos, np.ones(15))  # no longer than the padding
    with pytest.raises(ValueError) as old:
        signal.sosfiltfilt(sos, np.ones(15))
    assert str(new.value) == str(old.value)
    x = np.arange(100, dtype=np.float32)
    assert _same(zerophase.sosfiltfilt(sos, x), signal.sosfiltfilt(sos, x))
    cube = np.random.default_rng(0).standard_normal((3, 200, 2))
    assert _same(zerophase.sosfiltfilt(sos, cube, axis=1),
                 signal.sosfiltfilt(sos, cube, axis=1))


def test_a_design_is_each_callers_own() -> None:
    a = zerophase.butter_sos(4, 40.0, 500.0)
    a[0, 0] = 7.0
    assert zerophase.butter_sos(4, 40.0, 500.0)[0, 0] != 7.0


def _by_scipy(patch: pytest.MonkeyPatch) -> None:
    """The fast paths replaced by the SciPy calls they stand for."""
    patch.setattr(zerophase, "_fast", lambda sos, x, axis: False)
    patch.setattr(zerophase, "_butter", lambda order, fc, fs, band: np.asarray(
        signal.butter(order, fc, btype=band, fs=fs, output="sos"), dtype=np.float64))


def _fields(d: kinematics.EquationData) -> dict[str, object]:
    return {f.name: getattr(d, f.name) for f in dataclasses.fields(d)}


def _equal(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and _same(a, b)
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(map(_equal, a, b))
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return _equal(tuple(_fields(a).values()), tuple(_fields(b).values()))  # type: ignore
    return a == b


@pytest.mark.parametrize(("gap", "closed"), [(0, False), (3, False), (0, True)])
def test_the_fits_data_are_those_made_with_scipy(gap: int, closed: bool) -> None:
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 3000, 500.0, seed=5), seed=1)

    def run() -> tuple[object, ...]:
        kinematics.PROJECTED.clear()
        kinematics.FRICTION.clear()
        d = equation_data(plant, rec, thrust_gap=gap, closed_loop=closed)
        cols = d.project(np.column_stack([d.x, d.v, d.a]))
        spec = d.filt
        return (_fields(d), cols, kinematic_mode(rec, spec), feedback_z(rec),
                noise_gap(d.sos))

    fast = run()
    with pytest.MonkeyPatch.context() as patch:
        _by_scipy(patch)
        slow = run()
    assert fast[0].keys() == slow[0].keys()  # type: ignore[attr-defined]
    for name in fast[0]:  # type: ignore[attr-defined]
        assert _equal(fast[0][name], slow[0][name]), name  # type: ignore[index]
    assert all(_equal(a, b) for a, b in zip(fast[1:], slow[1:], strict=True))


@pytest.mark.parametrize("shape", [(3500, 32), (700, 1), (400, 3), (5000, 40), (600,)])
def test_thinned_columns_are_scipys_trimmed_and_decimated(shape: tuple[int, ...]) -> None:
    """Filtered in kept buffers, trimmed and decimated: SciPy's bits, in an array of its
    own (a later call does not change it), C-contiguous."""
    rng = np.random.default_rng(len(shape) + shape[0])
    sos = zerophase.butter_sos(4, 40.0, 500.0)
    x, other = rng.standard_normal(shape), rng.standard_normal(shape)
    got = zerophase.thinned_columns(sos, x, 38, 5)
    want = np.ascontiguousarray(signal.sosfiltfilt(sos, x, axis=0)[38:shape[0] - 38:5])
    kept = got.copy()
    zerophase.thinned_columns(sos, other, 38, 5)
    assert got.flags.c_contiguous and got.flags.owndata
    assert _same(got, want) and np.array_equal(got, kept)
