"""The fit's hand-written fast paths give what the library calls they replace give, bit for
bit: the AR whitener's Yule-Walker solve and root test, and the speed prior's digest."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest
from scipy.linalg import solve_toeplitz
from scipy.signal import lfilter

from pmsm_sysid.core.discrepancy import local
from pmsm_sysid.core.discrepancy.local import best_bump
from pmsm_sysid.core.discrepancy.nonparam import fit_axis_with
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import SIGN_SMOOTHING_MPS, nominal_plant
from pmsm_sysid.core.plantfit import library, stats
from pmsm_sysid.core.plantfit.calibration import SpeedPrior, calibrated_friction
from pmsm_sysid.core.plantfit.kinematics import EquationData, equation_data, projected, thinned
from pmsm_sysid.core.plantfit.library import (
    FIRST_STAGE,
    FIXED,
    Effect,
    Family,
    columns,
    families,
    family_chunks,
    inputs_key,
    raw_columns,
)
from pmsm_sysid.core.plantfit.memo import content_key, read_only


def _autocorrelation(e: np.ndarray, lags: int = 20) -> np.ndarray:
    x = e - e.mean()
    n = len(x)
    return np.array([float(x[: n - j] @ x[j:]) for j in range(lags + 1)]) / n


def _residuals() -> list[np.ndarray]:
    """White, AR(1) near the unit circle, and low-passed AR(2) residuals of many lengths."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(60):
        e = rng.standard_normal(int(rng.integers(200, 4000)))
        if k % 3:
            e = lfilter([1.0], [1.0, -rng.uniform(0.5, 0.9995)], e)
        if k % 3 == 2:
            e = lfilter([1.0], [1.0, -1.6, 0.7], e)
        out.append(e)
    return out


def test_yule_walker_is_solve_toeplitz_bit_for_bit() -> None:
    for e in _residuals():
        r = _autocorrelation(e)
        for p in range(1, 21):
            assert np.array_equal(stats._yule_walker(r, p), solve_toeplitz(r[:p], r[1:p + 1]))


def test_a_singular_system_is_refused_as_solve_toeplitz_refuses_it() -> None:
    r = np.array([0.0, 1.0, 0.5])
    with pytest.raises(np.linalg.LinAlgError):
        solve_toeplitz(r[:2], r[1:3])
    with pytest.raises(np.linalg.LinAlgError):
        stats._yule_walker(r, 2)


def test_max_root_is_that_of_np_roots() -> None:
    for e in _residuals():
        r = _autocorrelation(e)
        for p in range(1, 21):
            poly = np.concatenate([[1.0], -solve_toeplitz(r[:p], r[1:p + 1])])
            assert stats._max_root(poly) == np.max(np.abs(np.roots(poly)))
    for poly in ([1.0, -0.5, 0.0], [1.0, 0.0], [1.0, -1.2, 0.0, 0.0], [1.0]):
        p = np.array(poly)
        want = float(np.max(np.abs(np.roots(p)))) if len(p) > 1 else 0.0
        assert stats._max_root(p) == want


def _ar_whitener_by_library(e: np.ndarray, max_order: int) -> np.ndarray:
    """The whitener with its three fast paths replaced by the library calls they stand for
    (solve_toeplitz for the Yule-Walker solve, np.roots for the root test) and by the root
    test of every order up to the first unstable one (none settled early)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(stats, "_yule_walker",
                      lambda r, p: solve_toeplitz(r[:p], r[1:p + 1]))
        patch.setattr(stats, "_max_root",
                      lambda poly: float(np.max(np.abs(np.roots(poly)))))
        patch.setattr(stats, "_settled", lambda lowest, best: False)
        return stats._ar_whitener(e, max_order)


def test_the_whitener_is_the_library_one() -> None:
    orders = set()
    for e in _residuals():
        for m in (20, 5):
            got = stats._ar_whitener(e, m)
            assert np.array_equal(got, _ar_whitener_by_library(e, m))
            orders.add(len(got) - 1)
    assert len(orders) > 3  # the cases reach several orders (and the unit-circle stop)


def test_the_root_test_stops_once_no_higher_order_can_win() -> None:
    """The orders above the last that could still lower the BIC are not root-tested, and
    the choice is that of testing every order (unstable orders met included)."""
    roots: dict[str, list[float]] = {"fast": [], "every": []}
    max_root = stats._max_root

    def counted(kind: str) -> Callable[[np.ndarray], float]:
        def run(poly: np.ndarray) -> float:
            roots[kind].append(max_root(poly))
            return roots[kind][-1]
        return run

    rng = np.random.default_rng(5)
    cases = _residuals() + [lfilter([1.0], [1.0, -1.999, 0.9991], rng.standard_normal(3000))
                            for _ in range(5)]  # a pole pair at 0.99955
    for e in cases:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(stats, "_max_root", counted("fast"))
            got = stats._ar_whitener(e, 20)
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(stats, "_max_root", counted("every"))
            patch.setattr(stats, "_settled", lambda lowest, best: False)
            want = stats._ar_whitener(e, 20)
        assert np.array_equal(got, want)
    assert len(roots["fast"]) < 0.7 * len(roots["every"])
    assert sum(r >= 0.999 for r in roots["every"]) >= 5  # the unit-circle stop is met


def test_a_non_finite_residual_is_refused_as_before() -> None:
    e = np.ones(300)
    e[7] = np.nan
    with pytest.raises(ValueError) as new:
        stats._ar_whitener(e, 20)
    with pytest.raises(ValueError) as old:
        _ar_whitener_by_library(e, 20)
    assert str(new.value) == str(old.value)


# --------------------------------------------------------------------------- prior digest


def test_read_only_follows_the_memory_to_its_owner() -> None:
    owner = np.arange(10.0)
    view = owner[2:]
    view.flags.writeable = False
    assert not read_only(view)  # the owner can still change it
    owner.flags.writeable = False
    assert read_only(owner) and read_only(owner[2:])
    assert read_only(np.frombuffer(b"\0" * 16))
    assert not read_only(np.zeros(3))


def test_the_prior_digest_is_its_content() -> None:
    rng = np.random.default_rng(8)
    v = rng.standard_normal(3000) * 0.05
    a = SpeedPrior.from_speeds(v, 2e-3, 1e-3)
    same = SpeedPrior._deconvolved(v.copy(), 2e-3, 1e-3)  # another object, same content
    other = SpeedPrior.from_speeds(v * 1.01, 2e-3, 1e-3)
    assert a.digest() == same.digest() != other.digest()
    assert a.digest() == content_key("speed prior arrays", a.grid, a.density, a.kernel)
    # a prior made of arrays that can change is hashed every time: a change is seen
    loose = SpeedPrior(a.grid.copy(), a.density.copy(), a.kernel.copy())
    before = loose.digest()
    loose.density[0] += 1e-3
    assert loose.digest() != before


def test_friction_columns_are_keyed_by_the_prior() -> None:
    """Two priors on the same speeds give each its own friction column (no false hit)."""
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 2000, 500.0, seed=1), seed=0)
    d = equation_data(plant, rec)
    assert d.prior is not None
    wide = SpeedPrior.from_speeds(np.concatenate([d.v_lo, d.v_hi]), 5 * d.speed_noise_mps,
                                  SIGN_SMOOTHING_MPS)
    d2 = dataclasses.replace(d, prior=wide)
    for data in (d, d2, d):
        want = calibrated_friction(data.prior, data.v_lo, data.v_hi, SIGN_SMOOTHING_MPS, 0.0)
        assert np.array_equal(data.friction(), want)
    assert not np.array_equal(d.friction(), d2.friction())


# --------------------------------------------------------------------------- family chunks


def _changed(value: object, rng: np.random.Generator) -> object:
    """The same kind of value, other content (None where there is no other of its kind)."""
    if isinstance(value, np.ndarray):
        return value * (1.0 + 0.01 * rng.standard_normal(value.shape)) + 1e-3
    if isinstance(value, bool):
        return not value
    if isinstance(value, float):
        return value * 1.37 + 1e-4
    if isinstance(value, SpeedPrior):
        return SpeedPrior._deconvolved(value.grid[::3] * 1.2, 3e-3, 1e-3)
    if isinstance(value, tuple) and value and isinstance(value[0], np.ndarray):
        return tuple(_changed(q, rng) for q in value)
    return None


def _fresh(fam: Family, data: EquationData) -> np.ndarray:
    """The family's filtered columns computed without any cache."""
    members = fam.members[:3]
    raw = np.concatenate([raw_columns(e, data) for e in members], axis=1)
    bounds = tuple(data.instants()) if data.parts else ()
    return projected(data.sos, raw, data.filt.edge, data.filt.decimation, bounds)


@pytest.mark.parametrize("noisy_reading", [False, True])
def test_a_family_chunk_key_follows_every_field_its_columns_read(noisy_reading: bool) -> None:
    """Each field of the data changed in turn: whenever a family's filtered columns change,
    its key does (no false hit), and the chunks served are the ones computed fresh."""
    rng = np.random.default_rng(4)
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 3000, 500.0, seed=2), seed=0)
    d = equation_data(plant, rec, thrust_gap=3 if noisy_reading else 0)
    assert (d.inst is not None) == noisy_reading
    fams = families(d)
    assert {f.name for f in fams} >= {"cogging", "thrust_ripple", "stribeck_friction",
                                      *FIXED}
    changed = 0
    for field in dataclasses.fields(EquationData):
        other = _changed(getattr(d, field.name), rng)
        if other is None:
            continue
        d2 = dataclasses.replace(d, **{field.name: other})
        for fam in fams:
            try:
                differ = not np.array_equal(_fresh(fam, d), _fresh(fam, d2))
            except (ValueError, IndexError):
                differ = True  # the changed data do not even fit together
            if differ:
                changed += 1
                assert inputs_key(fam.name, d) != inputs_key(fam.name, d2), (field.name,
                                                                            fam.name)
    assert changed > 20
    for fam in fams:  # what the scan gets is what is computed fresh (kept or not)
        for _ in range(2):
            got = np.concatenate([c[i] for _, c in family_chunks(
                Family(fam.name, fam.members[:3], 1.0), d) for i in range(len(c))], axis=1)
            want = _fresh(fam, d)
            if fam.name in FIRST_STAGE:
                want = d.instrument(want)
            assert np.array_equal(got, want)


# --------------------------------------------------------------------------- columns kept by inputs


@pytest.mark.parametrize("noisy_reading", [False, True])
def test_an_effects_columns_kept_by_inputs_are_those_projected(noisy_reading: bool) -> None:
    """``columns`` (kept by the effect's inputs) gives what projecting its raw columns
    gives, before and after the data change (no stale hit)."""
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 3000, 500.0, seed=6), seed=4)
    d = equation_data(plant, rec, thrust_gap=3 if noisy_reading else 0)
    d2 = dataclasses.replace(d, x=d.x + 1e-3, v=d.v * 1.01, v_iv=d.v_iv * 0.99,
                             a_iv=d.a_iv * 1.02, cmd=d.cmd + 0.5)
    effects = [Effect(n) for n in FIXED] + [
        Effect("cogging", pitch_m=0.0307, orders=(1, 2)), Effect("thrust_ripple", pitch_m=0.05),
        Effect("stribeck_friction", velocity_mps=0.01)]
    for data in (d, d2, d):
        for e in effects:
            got = columns(e, data)
            with pytest.MonkeyPatch.context() as patch:
                patch.setattr(library, "inputs_key", lambda name, data: None)
                want = columns(e, data)
            assert _same(got, want), e.name


def test_the_bumps_kept_by_position_are_those_projected() -> None:
    """The bump columns (kept by the position and the members) are those projected, when
    the position changes with the members the same (no stale hit)."""
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 3000, 500.0, seed=7), seed=5)
    d = equation_data(plant, rec)
    lo, hi = np.quantile(d.x, [0.2, 0.8])
    inner = (d.x > lo) & (d.x < hi)
    moved = dataclasses.replace(d, x=np.where(inner, d.x + 1e-6, d.x))
    members = local.local_grid(d)[0]
    assert members == local.local_grid(moved)[0]
    y = d.y + 0.3 * np.exp(-0.5 * ((thinned(d, d.x) - float(np.median(d.x))) / 2e-3) ** 2)
    for data in (d, moved, d):
        for start in (0, 16, len(members) - 5):
            chunk = members[start:start + 16]
            want = data.project(local._bumps(data.x, chunk))
            assert _same(local.bump_columns(data, chunk), want)
        got = best_bump(data, y, np.ones((d.n, 1)))
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(local, "bump_columns",
                          lambda data, chunk: data.project(local._bumps(data.x, chunk)))
            assert got == best_bump(data, y, np.ones((d.n, 1)))


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.strides == b.strides and np.array_equal(a, b)


@pytest.mark.parametrize("axis", ["time", "position", "position_friction", "position_local",
                                  "velocity", "thrust"])
def test_a_curves_columns_kept_by_its_axis_are_those_projected(axis: str) -> None:
    """A curve's filtered columns (kept by its axis values and range) are those projected,
    when the axis changes under the same curve too (no stale hit)."""
    plant = nominal_plant()
    rec = simulate(plant, make_excitation("paper-position", 3000, 500.0, seed=8), seed=6)
    d = equation_data(plant, rec, thrust_gap=3)
    model = fit_axis_with(d, d.y, np.ones((d.n, 1)), axis,
                          freq_hz=3.0 if axis == "time" else 0.0)[0]
    changed = dataclasses.replace(d, x=d.x * 1.001, v=d.v * 0.999, v_iv=d.v_iv * 1.002,
                                  force=d.force + 0.1, force_iv=None, t=d.t + 1e-3,
                                  v_lo=d.v_lo * 1.01)
    slower = dataclasses.replace(d, v_lo=d.v_lo * 0.5, v_hi=d.v_hi * 0.5)  # friction only
    for data in (d, changed, d, slower):
        assert _same(model.projected(data), data.project(model.raw(data)))
