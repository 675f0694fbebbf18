"""Results kept by content: a new array of the same values finds the result, a changed one
never does; callers get arrays of their own; the memory bound holds; and the fit's
projections, friction regressors and whitening filters are bit-identical with and without
the store."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.plantfit import kinematics, stats
from pmsm_sysid.core.plantfit.memo import ContentCache, content_key


def test_the_key_is_the_content_not_the_object() -> None:
    a = np.arange(12.0).reshape(3, 4)
    assert content_key("f", a, 2) == content_key("f", a.copy(), 2)
    assert content_key("f", a, 2) == content_key("f", np.asfortranarray(a), 2)
    b = a.copy()
    b[2, 3] += 1e-12
    others = [content_key("f", b, 2), content_key("f", a.reshape(4, 3), 2),
              content_key("f", a.astype(np.float32), 2), content_key("f", a, 3),
              content_key("g", a, 2), content_key("f", a[:, :3], 2)]
    assert len({content_key("f", a, 2), *others}) == 1 + len(others)


def test_a_hit_is_a_copy_the_caller_may_change() -> None:
    cache = ContentCache(1 << 20)
    calls = []

    def compute() -> np.ndarray:
        calls.append(1)
        return np.ones(10)

    first = cache.array(b"k", compute)
    first[:] = 5.0  # the caller's own array: the kept one is a copy
    second = cache.array(b"k", compute)
    assert len(calls) == 1 and cache.hits == 1 and cache.misses == 1
    np.testing.assert_array_equal(second, np.ones(10))
    second[:] = 7.0
    np.testing.assert_array_equal(cache.array(b"k", compute), np.ones(10))


def test_the_oldest_leave_first_and_the_bound_holds() -> None:
    cache = ContentCache(3 * 800)  # three arrays of 100 float64
    for k in range(5):
        cache.array(bytes([k]), lambda k=k: np.full(100, float(k)))
        assert cache.nbytes <= cache.max_bytes
    cache.array(bytes([2]), lambda: np.zeros(100))  # kept: moves to the front
    cache.array(bytes([5]), lambda: np.full(100, 5.0))
    hits = cache.hits
    assert cache.array(bytes([2]), lambda: np.zeros(100))[0] == 2.0
    assert cache.array(bytes([0]), lambda: np.full(100, -1.0))[0] == -1.0  # gone
    assert cache.array(bytes([3]), lambda: np.full(100, -1.0))[0] == -1.0  # gone
    assert cache.hits == hits + 1
    big = cache.array(b"big", lambda: np.zeros(1000))  # larger than the bound: not kept
    assert big.shape == (1000,) and cache.nbytes <= cache.max_bytes


@pytest.fixture()
def cold() -> Iterator[None]:
    for c in (kinematics.PROJECTED, kinematics.FRICTION, stats.WHITENERS):
        c.clear()
    yield
    for c in (kinematics.PROJECTED, kinematics.FRICTION, stats.WHITENERS):
        c.clear()


def test_the_fits_columns_are_the_same_with_and_without_the_store(cold: None) -> None:
    plant = nominal_plant()
    n = 3000
    rec = simulate(plant, make_excitation("aprbs", n, plant.sample_rate_hz, seed=3), seed=3)
    data = kinematics.equation_data(plant, rec)
    cols = np.column_stack([np.sin(np.arange(len(data.cmd) - 1) * k / 50.0)
                            for k in range(1, 5)])
    first = (data.project(cols), data.friction(), data.friction(0.004),
             stats.ar_whitener(data.y))
    hits = kinematics.PROJECTED.hits + kinematics.FRICTION.hits + stats.WHITENERS.hits
    again = (data.project(cols.copy()), data.friction(), data.friction(0.004),
             stats.ar_whitener(data.y.copy()))
    assert (kinematics.PROJECTED.hits + kinematics.FRICTION.hits + stats.WHITENERS.hits
            == hits + 4)
    stored = [kinematics.PROJECTED, kinematics.FRICTION, stats.WHITENERS]
    bounds = [c.max_bytes for c in stored]
    try:
        for c in stored:
            c.max_bytes = 0
            c.clear()
        fresh = (data.project(cols), data.friction(), data.friction(0.004),
                 stats.ar_whitener(data.y))
    finally:
        for c, b in zip(stored, bounds, strict=True):
            c.max_bytes = b
    for x, y, z in zip(first, again, fresh, strict=True):
        assert np.array_equal(x, y) and np.array_equal(x, z)
    assert not np.array_equal(data.friction(0.004), data.friction())


def test_shared_values_are_the_kept_object_and_the_count_bound_holds() -> None:
    cache = ContentCache(1 << 20, max_items=2)
    first = cache.shared(b"a", lambda: (1, 2), lambda v: 16)
    assert cache.shared(b"a", lambda: (3, 4), lambda v: 16) is first
    cache.shared(b"b", lambda: (5,), lambda v: 8)
    cache.shared(b"c", lambda: (6,), lambda v: 8)  # a third: the oldest goes
    assert cache.shared(b"a", lambda: (7,), lambda v: 8) == (7,)
    assert cache.hits == 1 and cache.nbytes <= 32
