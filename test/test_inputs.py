"""Position-only inputs: one causal differentiator offline and live, and the account of what
arrived (pure core, no ROS)."""

from __future__ import annotations

import numpy as np
import pytest

from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.online.inputs import DECIDE_AFTER, InputAligner, SignalCount, describe_inputs
from pmsm_sysid.core.recording.align import align_streams
from pmsm_sysid.core.recording.signals import SpeedDeriver, derive_speed

TOPICS = {"thrust": "/pmsm/thrust", "speed": "/pmsm/speed", "position": "/pmsm/position"}


def _streams(n: int, period_ns: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    ns = np.arange(n, dtype=np.int64) * period_ns + 3 * period_ns
    ns += rng.integers(-20, 21, size=n)  # the jitter of a real recording's stamps (EMPS)
    x = np.cumsum(rng.normal(size=n)) * 1e-4
    u = rng.normal(size=n)
    return ns, u, x


def test_derive_speed_is_the_causal_backward_difference() -> None:
    t = np.array([0.0, 0.001, 0.003, 0.004])
    x = np.array([0.0, 1e-3, 5e-3, 4e-3])
    v = derive_speed(t, x)
    np.testing.assert_allclose(v, [1.0, 1.0, 2.0, -1.0])
    # causal: changing a later position never changes an earlier speed
    x2 = x.copy()
    x2[3] = 9.0
    np.testing.assert_array_equal(derive_speed(t, x2)[:3], v[:3])
    with pytest.raises(DataError):
        derive_speed(t[:1], x[:1])
    with pytest.raises(DataError):
        derive_speed(np.array([0.0, 0.0, 1.0]), x[:3])


@pytest.mark.parametrize("period_ns", [1_000_000, 2_000_000])  # 1 kHz and 500 Hz
def test_live_derived_speed_equals_offline_bit_for_bit(period_ns: int) -> None:
    ns, u, x = _streams(600, period_ns)
    al = InputAligner()  # auto: no speed message ever comes
    out = []
    for k in range(len(ns)):
        out += al.push("thrust", int(ns[k]), float(u[k]))
        out += al.push("position", int(ns[k]), float(x[k]))
    out += al.flush()
    assert al.mode == "derived" and al.speed_derived
    rec, rep = align_streams((ns / 1e9, u), None, (ns / 1e9, x))
    assert rep.speed_derived and len(out) == len(rec) == 600
    live = np.array([s.values for s in out])
    np.testing.assert_array_equal(live[:, 0], rec.thrust)
    np.testing.assert_array_equal(live[:, 1], rec.speed)  # same function, same numbers
    np.testing.assert_array_equal(live[:, 2], rec.position)
    assert [s.index for s in out] == list(range(out[0].index, out[0].index + 600))
    assert al.stats.messages == 1200 and al.stats.unaligned == 0


def test_auto_takes_measured_speed_as_soon_as_it_arrives() -> None:
    ns, u, x = _streams(100, 2_000_000)
    al = InputAligner()
    out = []
    for k in range(100):
        out += al.push("thrust", int(ns[k]), float(u[k]))
        out += al.push("position", int(ns[k]), float(x[k]))
        out += al.push("speed", int(ns[k]), 7.0)
    assert al.mode == "measured" and len(out) >= 90
    assert all(s.values[1] == 7.0 for s in out)


def test_auto_waits_for_an_announced_speed_publisher() -> None:
    ns, u, x = _streams(200, 2_000_000)
    al = InputAligner(speed_expected=lambda: True)
    for k in range(2 * DECIDE_AFTER):  # positions first (discovery of the speed topic late)
        al.push("thrust", int(ns[k]), float(u[k]))
        al.push("position", int(ns[k]), float(x[k]))
    assert al.mode == "undecided" and al.samples_emitted == 0
    out = []
    for k in range(200):
        out += al.push("speed", int(ns[k]), 3.0)
    out += al.flush()
    assert al.mode == "measured" and all(s.values[1] == 3.0 for s in out)
    # every message is accounted for: aligned into a sample, or counted unaligned (the
    # speed of the first samples came later than the aligner's reorder window)
    st = al.stats
    assert st.messages == 4 * DECIDE_AFTER + 200
    assert 3 * len(out) + st.unaligned + st.duplicates + st.out_of_order == st.messages
    assert out


def test_speed_messages_ignored_when_derived_and_bad_options() -> None:
    al = InputAligner(speed_source="derived")
    al.push("speed", 0, 1.0)
    assert al.ignored == 1 and al.stats.unaligned == 1
    with pytest.raises(DataError):
        InputAligner(speed_source="guess")
    with pytest.raises(DataError):
        InputAligner(("thrust", "speed"), speed_source="derived")


def test_deriver_passes_over_non_finite_positions_and_restarts() -> None:
    d: SpeedDeriver[str] = SpeedDeriver()
    assert d.push(0, 0.0, "a") == []
    assert d.push(1_000_000_000, 1.0, "b") == [("a", 1.0), ("b", 1.0)]
    (got,) = d.push(2_000_000_000, float("nan"), "c")
    assert got[0] == "c" and np.isnan(got[1])
    assert d.push(3_000_000_000, 3.0, "d") == [("d", 1.0)]  # spans the bad sample
    assert d.push(0, 5.0, "e") == []  # clock restarted
    assert d.drain() == ["e"]


def test_describe_inputs_names_what_never_came() -> None:
    thrust = SignalCount()
    for k in range(1001):
        thrust.add(k * 1_000_000)
    rep = describe_inputs(TOPICS, {"thrust": thrust, "speed": SignalCount(),
                                   "position": SignalCount()}, "undecided", 0)
    assert rep.problem == "no messages on /pmsm/position: nothing could be aligned"
    assert rep.missing == ("/pmsm/speed", "/pmsm/position")
    assert rep.arrived["/pmsm/thrust"]["rate_hz"] == pytest.approx(1000.0)
    assert "never came: /pmsm/speed, /pmsm/position" in rep.line()
    none = describe_inputs(TOPICS, {}, "undecided", 0)
    assert none.problem is not None and none.problem.startswith("no messages on /pmsm/thrust")
    ok = describe_inputs(TOPICS, {"thrust": thrust, "position": thrust}, "derived", 1000)
    assert ok.problem is None and ok.speed == "derived from position"
    assert ok.line().startswith("inputs: /pmsm/thrust 1000 Hz, /pmsm/position 1000 Hz")
