"""IdentifierNode on live topics: wiring, message layouts, equality with the offline fit."""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.selection.identify import FitConfig, fit_narx
from pmsm_sysid.core.terms.model import NarxModel, Structure

pytestmark = pytest.mark.ros
PERIOD_NS = 2_000_000
SMALL = {"window": 300, "hop": 100, "queue_size": 32, "speed.ny": 3, "speed.nu": 3,
         "speed.terms": 6, "position.ny": 3, "position.nu": 3, "position.terms": 6,
         "method": "ofr"}


def _data(n: int, seed: int = 0) -> np.ndarray:
    """(thrust, speed, position) of a known quadratic NARX system driven by noise."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.6 * y[k - 1] - 0.2 * y[k - 2] + 0.8 * u[k - 1] + 0.2 * u[k - 1] * y[k - 1]
    y += 0.01 * rng.standard_normal(n)
    return np.stack([u, y, np.cumsum(y) * 0.002], axis=1)


class _Source:
    """A plain node publishing samples on the contract topics or as JointState."""

    def __init__(self, ctx: Any, joint: bool = False) -> None:
        from rclpy.node import Node
        from sensor_msgs.msg import JointState

        from pmsm_sysid.rosutil import data_qos, make_sample_messages
        from pmsm_sysid.topics import DEFAULT_NAMESPACE, INPUT_TYPES, input_topic

        self.node = Node("test_source", context=ctx)
        self._make = make_sample_messages
        if joint:
            # where ros2_control's joint_state_broadcaster publishes: the root namespace
            self.pub = self.node.create_publisher(JointState, "/joint_states", data_qos())
        else:
            self.pubs = {s: self.node.create_publisher(type(m), input_topic(DEFAULT_NAMESPACE, s),
                                                       data_qos())
                         for s, m in make_sample_messages(0, 0, 0, 0).items() if s in INPUT_TYPES}

    def sample(self, k: int, row: np.ndarray, signals: tuple[str, ...] | None = None) -> None:
        for sig, msg in self._make(k * PERIOD_NS, *row).items():
            if signals is None or sig in signals:
                self.pubs[sig].publish(msg)

    def joint(self, k: int, row: np.ndarray, names: list[str]) -> None:
        from sensor_msgs.msg import JointState

        from pmsm_sysid.rosutil import stamp_from_ns

        msg = JointState(name=names)
        msg.header.stamp = stamp_from_ns(k * PERIOD_NS)
        i = names.index("axis") if "axis" in names else 0
        vals = [[0.0] * len(names) for _ in range(3)]
        for col in range(3):
            vals[col][i] = float(row[col])
        msg.effort, msg.velocity, msg.position = vals
        if np.isnan(row[1]):  # a position-only joint: no velocity array at all
            msg.velocity = []
        self.pub.publish(msg)


def _spin_until(executor: Any, done: Any, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    assert done(), "timed out"


def _run(ctx: Any, data: np.ndarray, params: dict[str, Any], joint: list[str] | None = None,
         signals: tuple[str, ...] | None = None,
         ) -> tuple[Any, list[dict[str, Any]], list[Any], list[Any]]:
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from pmsm_sysid.nodes.identifier_node import IdentifierNode
    from pmsm_sysid.topics import DEFAULT_NAMESPACE, MODEL, VALIDATION, topic_name

    node = IdentifierNode(context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in {**SMALL, **params}.items()])
    src = _Source(ctx, joint=joint is not None)
    models: list[dict[str, Any]] = []
    vals: list[Any] = []
    src.node.create_subscription(String, topic_name(DEFAULT_NAMESPACE, MODEL),
                                 lambda m: models.append(json.loads(m.data)), 100)
    src.node.create_subscription(DiagnosticArray, topic_name(DEFAULT_NAMESPACE, VALIDATION),
                                 vals.append, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(src.node)
    per = 3 if signals is None else len(signals)
    try:
        # publish nothing before every input and result topic is matched (discovery)
        results = (topic_name(DEFAULT_NAMESPACE, MODEL), topic_name(DEFAULT_NAMESPACE, VALIDATION))
        pubs = [*src.pubs.values()] if joint is None else [src.pub]
        pubs += [p for p in node.publishers if p.topic_name in results]
        assert len(pubs) == (1 if joint is not None else 3) + 2
        _spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in pubs), 30.0)
        for k, row in enumerate(data):
            src.joint(k, row, joint) if joint is not None else src.sample(k, row, signals)
            if k % 50 == 49:
                _spin_until(ex, lambda k=k: node.engine.aligner.stats.messages >= per * (k - 10))
        n_msgs = per * len(data)  # a JointState counts as its three signals
        _spin_until(ex, lambda: node.engine.aligner.stats.messages >= n_msgs)
        node.engine.flush()
        assert node.engine.wait_idle(60)
        node.publish_results()
        expected = node.models_published
        _spin_until(ex, lambda: len(models) >= expected)
        stats = node.engine.stats
        summary = node.summary()
        return stats, models, vals, summary["errors"] if signals is None else summary
    finally:
        ex.shutdown()
        node.destroy_node()
        src.node.destroy_node()


def test_models_on_the_topics_equal_the_offline_fit_of_the_same_window(ros_context: Any) -> None:
    data = _data(1300)
    stats, models, vals, errors = _run(ros_context, data, {})
    assert errors == []
    assert stats.samples_received == 1300 and stats.samples_dropped == 0
    assert stats.samples_missing == 0 and stats.unaligned == 0
    # windows end on the grid k+1 = 0 mod hop once window + 3 lag samples are in: 400..1300
    assert stats.windows_skipped == 0 and stats.windows_fitted == stats.windows_due == 10
    speed = [m for m in models if m["output"] == "speed"]
    assert [m["window"]["stop_index"] for m in speed] == list(range(400, 1301, 100))
    cfg = FitConfig(structure=Structure(3, 3, 2, 1), n_terms=6, method="ofr")
    for m in speed:
        a, b = m["window"]["start_index"], m["window"]["stop_index"]
        assert m["window"]["start_stamp"] == pytest.approx(a * 0.002)
        assert m["window"]["end_stamp"] == pytest.approx((b - 1) * 0.002)
        ref = fit_narx(data[a - 3:b, 1], data[a - 3:b, 0], cfg, 500.0)  # as identify a:b
        got = NarxModel.from_dict(m)
        assert got.term_names == ref.model.term_names
        np.testing.assert_allclose(got.estimates, ref.model.estimates, rtol=0, atol=1e-12)
        assert m["model_id"] == f"speed/{b // 100}" and m["sample_rate_hz"] == 500.0
        assert set(m) >= {"input", "output", "structure", "terms", "validation", "timing_ms",
                          "window", "fit_time_ms"}
        assert m["validation"]["validation"] is None  # independent data come later
    # the true system's terms are found on every window after the first (3 lags of history)
    assert {"y(k-1)", "y(k-2)", "u(k-1)", "y(k-1)u(k-1)"} <= set(speed[-1]["terms"][i]["name"]
                                                                  for i in range(6))
    statuses = [s for arr in vals for s in arr.status]
    xval = [s for s in statuses if s.name == "identifier/cross_validation/speed"]
    # the model of the window ending at s is validated on the window starting at s: s <= 1000
    assert len(xval) == 7
    for s in xval:
        kv = {v.key: v.value for v in s.values}
        on = json.loads(kv["validated_on"])
        model_stop = int(s.hardware_id.split("/")[1]) * 100
        assert on["start_stamp"] == pytest.approx(model_stop * 0.002)
        assert json.loads(kv["r2"]) > 0.9 and json.loads(kv["pass"]) == (s.level == b"\x00")


def test_joint_state_layout(ros_context: Any) -> None:
    data = _data(700, seed=1)
    stats, models, _, errors = _run(
        ros_context, data, {"input_layout": "joint_state", "joint_name": "axis"},
        joint=["base", "axis"])
    assert errors == [] and stats.samples_received == 700 and stats.unaligned == 0
    assert sorted({m["output"] for m in models}) == ["position", "speed"]
    assert len(models) == 2 * 4  # windows ending at 400, 500, 600, 700


def test_joint_state_without_the_joint_is_counted_not_used(ros_context: Any) -> None:
    stats, models, _, _ = _run(ros_context, _data(120), {"input_layout": "joint_state",
                                                         "joint_name": "missing"},
                               joint=["axis"])
    assert stats.samples_received == 0 and stats.unaligned == 3 * 120 and models == []


@pytest.mark.parametrize("params,match", [
    ({"input_layout": "can_bus"}, "input_layout"),
    ({"input_layout": "joint_state"}, "joint_name"),
    ({"outputs": ["torque"]}, "outputs"),
    ({"method": "lasso"}, "method"),
    ({"hop": 0}, "hop"),
])
def test_bad_parameters_raise_one_clear_error(ros_context: Any, params: dict[str, Any],
                                              match: str) -> None:
    from rclpy.parameter import Parameter

    from pmsm_sysid.core.errors import PmsmSysidError
    from pmsm_sysid.nodes.identifier_node import IdentifierNode

    with pytest.raises(PmsmSysidError, match=match):
        IdentifierNode(context=ros_context,
                       parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def _derived_reference(data: np.ndarray) -> Any:
    """The offline recording of thrust and position only: speed derived on reading."""
    from pmsm_sysid.core.recording.align import align_streams

    t = np.arange(len(data)) * PERIOD_NS / 1e9
    rec, _ = align_streams((t, data[:, 0]), None, (t, data[:, 2]))
    return rec


def test_position_only_topics_give_the_offline_models_of_derived_speed(ros_context: Any) -> None:
    from pmsm_sysid.core.selection.identify import identify_recording

    data = _data(800, seed=2)
    stats, models, _, summary = _run(ros_context, data, {}, signals=("thrust", "position"))
    assert summary["errors"] == [] and summary["speed_derived"] is True
    assert stats.samples_received == 800 and stats.unaligned == 0
    ins = summary["inputs"]
    assert ins["missing"] == ["/pmsm/speed"] and ins["problem"] is None
    assert ins["speed"] == "derived from position"
    assert ins["arrived"]["/pmsm/thrust"]["rate_hz"] == pytest.approx(500.0)
    rec = _derived_reference(data)
    assert len(models) == 2 * 5  # windows ending at 400 .. 800
    for m in models:
        a, b = m["window"]["start_index"], m["window"]["stop_index"]
        assert m["speed_derived"] is (m["output"] == "speed")
        st = m["structure"]  # position: linear, in increments (the defaults)
        cfg = FitConfig(structure=Structure(st["ny"], st["nu"], st["degree"], st["delay"]),
                        n_terms=6, method="ofr")
        ref = identify_recording(rec, output=m["output"], config=cfg, estimate=(a, b),
                                 validate=None, form=m["form"])
        got = NarxModel.from_dict(m)
        assert got.term_names == ref.model.term_names
        np.testing.assert_allclose(got.estimates, ref.model.estimates, rtol=1e-12, atol=0)


def test_position_only_joint_state_derives_speed(ros_context: Any) -> None:
    data = _data(500, seed=3)
    data[:, 1] = np.nan  # no velocity array in the messages
    stats, models, _, errors = _run(
        ros_context, data, {"input_layout": "joint_state", "joint_name": "axis"},
        joint=["axis"])
    assert errors == [] and stats.samples_received == 500 and stats.samples_dropped == 0
    rec = _derived_reference(data)
    speed = [m for m in models if m["output"] == "speed"]
    assert speed and all(m["speed_derived"] for m in speed)
    cfg = FitConfig(structure=Structure(3, 3, 2, 1), n_terms=6, method="ofr")
    a, b = speed[-1]["window"]["start_index"], speed[-1]["window"]["stop_index"]
    ref = fit_narx(rec.speed[a - 3:b], rec.thrust[a - 3:b], cfg, 500.0)
    np.testing.assert_allclose(NarxModel.from_dict(speed[-1]).estimates, ref.model.estimates,
                               rtol=1e-12, atol=0)


def test_a_run_without_position_says_so(ros_context: Any) -> None:
    """Thrust and speed arrive, position never does: nothing can be aligned, and the node
    says which topic is missing (log, summary) within its report delay."""
    data = _data(300, seed=4)
    stats, models, _, summary = _run(ros_context, data, {"inputs_report_s": 0.0},
                                     signals=("thrust", "speed"))
    assert stats.samples_received == 0 and models == []
    ins = summary["inputs"]
    assert ins["problem"] == "no messages on /pmsm/position: nothing could be aligned"
    assert ins["missing"] == ["/pmsm/position"]
    assert set(ins["arrived"]) == {"/pmsm/thrust", "/pmsm/speed"}
    assert summary["input_log"] and summary["input_log"][-1].startswith(
        "no messages on /pmsm/position: nothing could be aligned (inputs: /pmsm/thrust 500 Hz")


def test_a_window_status_carries_the_runs_windows() -> None:
    """Each window's cross-validation status on <ns>/validation says how the run stands:
    windows passed so far and whether that is as often as a correct model passes (the run
    summary's binomial test against 1 in 20), so that a reader of one failed window knows
    whether it is chance."""
    from pmsm_sysid.nodes.identifier_status import validation_status

    tests = {k: {"max_abs": 0.05, "band": 0.062, "pass": k != "ee", "n_outside": 1,
                 "n_lags": 20, "n_allowed": 4} for k in ("ee", "ue", "u2e", "u2e2", "e_eu")}
    v = {"output": "speed", "model_id": "speed/9", "pass": False, "min_r2": 0.9,
         "osa_r2": 0.999, "validated_on": {"seq": 13},
         "free_run": {"nrmse": 0.06, "r2": 0.996, "diverged": False},
         "correlation_tests": tests, "correlation_tests_validation": tests}
    ok = validation_status(v, count=[50, 52])
    values = {kv.key: kv.value for kv in ok.values}
    assert (values["windows_passed"], values["windows_validated"]) == ("50", "52")
    assert values["run_consistent"] == "true"
    assert ok.message.startswith("window fail: ")
    assert ok.message.endswith("; run: 50/52 windows passed, as a correct model does (1 in 20 "
                               "fail by chance)")
    assert json.loads(values["corr.ee"])["n_allowed"] == 4
    # the same count with windows that do not overlap: the plain binomial tail
    assert "(p = 7.7e-06)" in validation_status(v, count=[40, 52], shift=2.0).message
    bad = validation_status(v, count=[40, 52])
    assert "more failures than chance (p = 0.00033)" in bad.message
    assert {kv.key: kv.value for kv in bad.values}["run_consistent"] == "false"
