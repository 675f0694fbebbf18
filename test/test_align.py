"""Stamp alignment (core/align.py) on synthetic streams whose truth is known by construction."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.recording.align import align_streams, mutual_nearest, robust_period

FS = 500.0
DT = 1.0 / FS


def _streams(n: int = 200, seed: int = 0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Three streams on the same stamps; values encode the sample index so matches are checkable."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT + 10.0
    k = np.arange(n, dtype=float)
    return {"thrust": (t.copy(), 1000.0 + k + rng.uniform(0, 0.1, n)),
            "speed": (t.copy(), 2000.0 + k), "position": (t.copy(), 3000.0 + k)}


def _identity(rep, k: int) -> bool:
    """Every message is aligned, non-finite, duplicate or unaligned, exactly once."""
    total = rep.n_thrust + rep.n_speed + rep.n_position
    return total == k * rep.n_aligned + rep.n_nonfinite + rep.n_duplicates + rep.n_unaligned


def test_identical_stamps_align_exactly() -> None:
    s = _streams()
    rec, rep = align_streams(s["thrust"], s["speed"], s["position"], source="synthetic")
    assert len(rec) == 200 and rep.n_aligned == 200
    assert (rep.n_unaligned, rep.n_duplicates, rep.n_out_of_order, rep.n_nonfinite,
            rep.n_gaps) == (0, 0, 0, 0, 0)
    np.testing.assert_array_equal(rec.t, s["position"][0])
    np.testing.assert_array_equal(rec.thrust, s["thrust"][1])
    np.testing.assert_array_equal(rec.speed, s["speed"][1])
    assert rec.sample_rate_hz == pytest.approx(FS, rel=1e-12)
    assert rep.tolerance_s == pytest.approx(DT / 2, rel=1e-12)
    assert not rec.speed_derived and rec.source == "synthetic"
    assert _identity(rep, 3)


def test_jitter_within_tolerance_pairs_the_right_messages() -> None:
    s = _streams(n=500, seed=1)
    rng = np.random.default_rng(2)
    tu = s["thrust"][0] + rng.uniform(-0.45, 0.45, 500) * DT
    tv = s["speed"][0] + rng.uniform(-0.2, 0.2, 500) * DT
    rec, rep = align_streams((tu, s["thrust"][1]), (tv, s["speed"][1]), s["position"])
    assert rep.n_aligned == 500 and rep.n_unaligned == 0
    # index k travels with each value: thrust 1000+k, speed 2000+k, position 3000+k
    np.testing.assert_array_equal(np.floor(rec.thrust) - 1000, rec.position - 3000)
    np.testing.assert_array_equal(rec.speed - 2000, rec.position - 3000)


def test_offset_beyond_tolerance_aligns_nothing() -> None:
    s = _streams()
    late = (s["thrust"][0] + 0.3 * DT, s["thrust"][1])
    with pytest.raises(DataError, match="only 0 samples align"):
        align_streams(late, s["speed"], s["position"], tolerance_s=0.2 * DT)
    _, rep = align_streams(late, s["speed"], s["position"])  # default tolerance DT/2
    assert rep.n_aligned == 200


def test_duplicates_dropped_first_received_kept() -> None:
    s = _streams()
    tu, u = s["thrust"]
    tx, x = s["position"]
    # thrust: stamps 5 and 9 received twice (second copy has a different value)
    tu2 = np.concatenate([tu[:6], [tu[5]], tu[6:10], [tu[9]], tu[10:]])
    u2 = np.concatenate([u[:6], [-1.0], u[6:10], [-2.0], u[10:]])
    tx2 = np.concatenate([tx[:50], [tx[49]], tx[50:]])
    x2 = np.concatenate([x[:50], [x[49]], x[50:]])
    rec, rep = align_streams((tu2, u2), s["speed"], (tx2, x2))
    assert rep.n_duplicates == 3 and rep.n_aligned == 200 and rep.n_unaligned == 0
    assert rep.n_thrust == 202 and rep.n_position == 201
    np.testing.assert_array_equal(rec.thrust, u)  # -1 and -2 never reach the recording
    assert _identity(rep, 3)


def test_out_of_order_sorted_and_counted() -> None:
    s = _streams()
    tv, v = s["speed"]
    order = np.arange(200)
    order[[10, 11]] = [11, 10]          # one late message
    order[[50, 51, 52]] = [52, 50, 51]  # 52 jumps ahead: 50 and 51 arrive late
    rec, rep = align_streams(s["thrust"], (tv[order], v[order]), s["position"])
    assert rep.n_out_of_order == 3 and rep.n_aligned == 200
    np.testing.assert_array_equal(rec.speed, v)
    assert np.all(np.diff(rec.t) > 0)


def test_missing_messages_never_invented() -> None:
    s = _streams(n=300)
    keep = np.ones(300, dtype=bool)
    keep[[7, 100, 101, 250]] = False
    tu, u = s["thrust"]
    rec, rep = align_streams((tu[keep], u[keep]), s["speed"], s["position"])
    assert rep.n_aligned == 296
    assert rep.n_unaligned == 2 * 4  # speed and position at the four stamps without thrust
    assert not np.isin(s["position"][1][~keep], rec.position).any()
    # every output thrust value is an input thrust value from a stamp within tolerance
    src = dict(zip(tu[keep].tolist(), u[keep].tolist(), strict=True))
    assert all(src[t] == v for t, v in zip(rec.t.tolist(), rec.thrust.tolist(), strict=True))
    assert rep.n_gaps == 3  # the output skips stamps 7, 100-101 and 250
    assert _identity(rep, 3)


def test_gap_in_all_streams_counted() -> None:
    s = _streams(n=300)
    keep = np.ones(300, dtype=bool)
    keep[120:125] = False  # a 6-period step once
    cut = {k: (v[0][keep], v[1][keep]) for k, v in s.items()}
    rec, rep = align_streams(cut["thrust"], cut["speed"], cut["position"])
    assert rep.n_gaps == 1 and rep.n_aligned == 295 and rep.n_unaligned == 0
    assert rec.sample_rate_hz == pytest.approx(FS, rel=1e-9)


def test_nonfinite_messages_dropped_and_counted() -> None:
    s = _streams()
    u = s["thrust"][1].copy()
    u[[3, 40]] = [np.nan, np.inf]
    tx = s["position"][0].copy()
    tx[77] = np.nan
    rec, rep = align_streams((s["thrust"][0], u), s["speed"], (tx, s["position"][1]))
    assert rep.n_nonfinite == 3 and rep.n_aligned == 197
    assert rep.n_unaligned == 2 * 2 + 2 * 1
    assert np.all(np.isfinite(rec.thrust)) and np.all(np.isfinite(rec.t))
    assert _identity(rep, 3)


def test_missing_speed_is_derived_and_marked() -> None:
    n, f = 2000, 3.0
    t = np.arange(n) * DT
    x = 0.01 * np.sin(2 * np.pi * f * t)
    rec, rep = align_streams((t, np.zeros(n)), None, (t, x))
    assert rec.speed_derived and rep.speed_derived and rep.n_speed == 0
    # the causal backward difference is the mean speed over the interval ending at t_k:
    # the speed at its middle t_k - DT/2 to within (third derivative of x) * DT^2 / 24
    mid = 0.01 * 2 * np.pi * f * np.cos(2 * np.pi * f * (t - DT / 2))
    bound = 0.01 * (2 * np.pi * f) ** 3 * DT**2 / 24 * 1.01
    assert np.max(np.abs(rec.speed[1:] - mid[1:])) <= bound
    assert rec.speed[0] == rec.speed[1]  # the first sample has no predecessor
    assert _identity(rep, 2)
    assert "derived from position" in rep.summary()


def test_mutual_nearest_uses_each_message_once() -> None:
    r = np.array([0.0, 1.0, 1.1, 2.0, 3.0])
    s = np.array([0.05, 1.06, 2.9])
    i, j = mutual_nearest(r, s, tol=0.5)
    assert i.tolist() == [0, 2, 4] and j.tolist() == [0, 1, 2]  # 1.06 goes to 1.1 only


def test_robust_period_unbiased_by_quantised_jitter() -> None:
    steps = np.array([0.99998e-3, 1.00002e-3] * 50 + [0.99998e-3] * 3)  # median is biased
    t = np.concatenate([[0.0], np.cumsum(steps)])
    assert robust_period(t) == pytest.approx(np.mean(steps), rel=1e-12)
    t_gap = np.concatenate([t, [t[-1] + 0.01]])
    assert robust_period(t_gap) == pytest.approx(np.mean(steps), rel=1e-12)


@pytest.mark.parametrize("case", ["few", "lengths", "2d", "tolerance", "one_position"])
def test_bad_input_raises_data_error(case: str) -> None:
    t = np.arange(10) * DT
    v = np.zeros(10)
    args: dict[str, object] = {"thrust": (t, v), "speed": None, "position": (t, v)}
    kw: dict[str, object] = {}
    if case == "few":
        args["thrust"] = (t[:2], v[:2])
    elif case == "lengths":
        args["position"] = (t, v[:5])
    elif case == "2d":
        args["position"] = (t.reshape(2, 5), v.reshape(2, 5))
    elif case == "tolerance":
        kw["tolerance_s"] = -1.0
    else:
        args["position"] = (t[:1], v[:1])
    with pytest.raises(DataError):
        align_streams(args["thrust"], args["speed"], args["position"], **kw)  # type: ignore[arg-type]


def test_report_dict_and_summary() -> None:
    s = _streams()
    _, rep = align_streams(s["thrust"], s["speed"], s["position"])
    d = rep.to_dict()
    assert d["n_aligned"] == 200 and d["speed_derived"] is False
    assert rep.summary().startswith("200 samples aligned") and "\n" not in rep.summary()


def _reference_mutual(r: np.ndarray, s: np.ndarray, tol: float) -> set[tuple[int, int]]:
    """Brute force: nearest by full distance matrix, ties to the lower index."""
    if len(r) == 0 or len(s) == 0:
        return set()
    d = np.abs(r[:, None] - s[None, :])
    nr, ns = np.argmin(d, axis=1), np.argmin(d, axis=0)
    return {(i, int(nr[i])) for i in range(len(r))
            if ns[nr[i]] == i and d[i, nr[i]] <= tol}


stamps = st.lists(st.floats(0.0, 1.0, allow_nan=False).map(lambda x: round(x, 4)),
                  min_size=0, max_size=40)
values = st.floats(-1e6, 1e6, allow_nan=False)


@st.composite
def related_stamps(draw: st.DrawFn) -> tuple[list[float], list[float] | None, list[float],
                                             float | None]:
    """Streams drawn from one list of stamps (0.5 ms apart or more, within 1 s): position
    has them all, thrust and speed most of them, exact or moved by up to 0.1 ms, plus
    stamps of their own, in any order; speed is absent in about a third of the draws. The
    tolerance is the default or at least 0.2 ms (0 when nothing is moved)."""
    base = [k * 5e-4 for k in draw(st.lists(st.integers(0, 2000), min_size=6, max_size=40,
                                            unique=True))]
    jitter = draw(st.sampled_from([0.0, 1e-4]))

    def one() -> list[float]:
        kept = [b + draw(st.floats(-jitter, jitter)) for b in base
                if draw(st.booleans()) or draw(st.booleans())]
        return draw(st.permutations(kept + draw(st.lists(st.floats(0.0, 1.0), max_size=5))))

    tu, tv = one(), (None if draw(st.integers(0, 2)) == 0 else one())
    tol = draw(st.one_of(st.none(), st.just(0.0) if jitter == 0 else st.nothing(),
                         st.floats(2e-4, 0.2)))
    return tu, tv, draw(st.permutations(base)), tol


#: Of the 200 examples drawn from common stamps, at least this many must align (the
#: property is checked on them); unrelated streams seldom align, which is checked too.
MIN_ALIGNED = 120


def _check_alignment(tu: list[float], tv: list[float] | None, tx: list[float],
                     data: st.DataObject, tol: float | None) -> bool:
    """Align the streams (random values); True if they aligned and the result holds."""
    def vals(n: int) -> list[float]:
        return data.draw(st.lists(values, min_size=n, max_size=n))

    thrust, position = (tu, vals(len(tu))), (tx, vals(len(tx)))
    speed = None if tv is None else (tv, vals(len(tv)))
    try:
        rec, rep = align_streams(thrust, speed, position, tolerance_s=tol)
    except DataError as exc:
        assert "\n" not in str(exc)
        return False
    assert rep.n_aligned == len(rec) >= 3
    assert np.all(np.diff(rec.t) > 0)
    assert _identity(rep, 2 if speed is None else 3)
    assert rep.n_aligned <= min(len(set(tu)), len(set(tx)))
    assert np.all(np.isfinite(rec.speed))
    pairs = set(zip(tu, thrust[1], strict=True))
    for t_k, u_k in zip(rec.t.tolist(), rec.thrust.tolist(), strict=True):
        assert any(abs(a - t_k) <= rep.tolerance_s and b == u_k for a, b in pairs)
    return True


def test_align_property() -> None:
    """Aligned samples are increasing, accounted for, finite and made of received pairs;
    checked on streams drawn from common stamps (MIN_ALIGNED of them at least must align)
    and on unrelated streams (mostly a one-line DataError)."""
    aligned: list[bool] = []

    @settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(streams=related_stamps(), data=st.data())
    def related(streams, data) -> None:
        tu, tv, tx, tol = streams
        aligned.append(_check_alignment(tu, tv, tx, data, tol))

    @settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(tu=stamps, tv=st.one_of(st.none(), stamps), tx=stamps, data=st.data(),
           tol=st.one_of(st.none(), st.floats(0.0, 0.2)))
    def unrelated(tu, tv, tx, data, tol) -> None:
        _check_alignment(tu, tv, tx, data, tol)

    related()
    assert sum(aligned) >= MIN_ALIGNED, f"only {sum(aligned)} of {len(aligned)} examples aligned"
    unrelated()


@settings(max_examples=300, deadline=None)
@given(r=stamps, s=stamps, tol=st.floats(0.0, 0.5))
def test_mutual_nearest_matches_brute_force(r, s, tol) -> None:
    ru, su = np.unique(np.array(r, dtype=float)), np.unique(np.array(s, dtype=float))
    i, j = mutual_nearest(ru, su, tol)
    assert set(zip(i.tolist(), j.tolist(), strict=True)) == _reference_mutual(ru, su, tol)
    assert np.all(np.diff(i) > 0) and np.all(np.diff(j) > 0)


def _late(ts: list[float]) -> int:
    """Messages stamped earlier than one already received (the report's definition)."""
    seen, late = -np.inf, 0
    for x in ts:
        late += x < seen
        seen = max(seen, x)
    return late


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(3, 60), data=st.data(), with_speed=st.booleans())
def test_align_counts_on_jittered_grid(n: int, data, with_speed: bool) -> None:
    """Grid streams with drops, jitter < 0.4 period, duplicates and shuffles: exact counts."""
    def stream(jitter: float) -> tuple[list[float], list[float], set[int], int]:
        present = sorted(data.draw(st.sets(st.integers(0, n - 1), min_size=0, max_size=n)))
        j = data.draw(st.lists(st.floats(-jitter, jitter), min_size=len(present),
                               max_size=len(present)))
        ts = [k * DT + jj * DT for k, jj in zip(present, j, strict=True)]
        vs = [float(k) for k in present]
        dups = data.draw(st.lists(st.sampled_from(range(len(ts))), max_size=5)) if ts else []
        ts += [ts[d] for d in dups]
        vs += [-1.0] * len(dups)  # a duplicate never reaches the output
        perm = data.draw(st.permutations(range(len(ts))))
        return [ts[p] for p in perm], [vs[p] for p in perm], set(present), len(dups)

    tu, u, pu, du = stream(0.4)
    tx, x, px, dx = stream(0.0)
    tv, v, pv, dv = stream(0.4) if with_speed else ([], [], set(range(n)), 0)
    both = pu & px & pv
    first: dict[float, float] = {}
    for a, b in zip(tx, x, strict=True):
        first.setdefault(a, b)  # the first received copy of a stamp is the one kept
    try:
        rec, rep = align_streams((tu, u), (tv, v) if with_speed else None, (tx, x),
                                 tolerance_s=0.5 * DT)
    except DataError:
        assert len(both) < 3
        return
    assert rep.n_aligned == len(both)
    assert rep.n_duplicates == du + dx + dv
    assert rep.n_out_of_order == _late(tu) + _late(tx) + (_late(tv) if with_speed else 0)
    assert rec.position.tolist() == [first[k * DT] for k in sorted(both)]
    assert np.round(rec.t / DT).tolist() == sorted(both)
    assert all(a in (k, -1.0) for a, k in zip(rec.thrust.tolist(), sorted(both), strict=True))
    assert _identity(rep, 3 if with_speed else 2)
