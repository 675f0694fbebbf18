"""Two pipelines side by side on one domain: each lives in its own namespace.

Nodes are named under the namespace (``/a/pmsm_identifier``), every topic a pipeline creates
(inputs, models, ridges, ridge frequencies, validation, change events) lives under it, and
neither pipeline sees the other's samples or results.
"""

from __future__ import annotations

import time
import uuid
from typing import Any

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SMALL = {"outputs": ["speed"], "window": 300, "hop": 100, "speed.ny": 4, "speed.nu": 4,
         "speed.terms": 6, "method": "ofr"}


def test_two_namespaced_pipelines_share_a_domain_without_cross_talk(ros_context: Any) -> None:
    from pmsm_sysid.app import build_pipeline

    tag = uuid.uuid4().hex[:6]
    ns_a, ns_b = f"/a{tag}", f"/b{tag}"
    with build_pipeline(clock="sim", seed=1, namespace=ns_a, context=ros_context,
                        identifier_params=SMALL) as a, \
            build_pipeline(clock="sim", seed=2, namespace=ns_b, context=ros_context,
                           identifier_params=SMALL) as b:
        nodes = set(a.identifier.get_node_names_and_namespaces())
        for ns in (ns_a, ns_b):
            assert {("pmsm_sim", ns), ("pmsm_identifier", ns), ("pmsm_gfrf", ns)} <= nodes
        topics = {name for name, _ in a.identifier.get_topic_names_and_types()}
        for ns in (ns_a, ns_b):
            assert {f"{ns}/{t}" for t in ("thrust", "speed", "position", "model", "ridges",
                                          "ridge_frequencies", "validation", "change")} <= topics
        assert not [t for t in topics if t.startswith("/pmsm_sysid")]
        got = _listen(a, ns_a, ns_b)
        # a runs first while b sits idle: with any cross-talk b's identifier would hold a's
        # samples, and a's collector b's models
        a.run(2.0)
        b.run(3.0)
        a.finish()
        b.finish()
        sa, sb = a.summary(), b.summary()
        health = {f"pmsm_sysid: {ns} {kind}" for ns in (ns_a, ns_b)
                  for kind in ("sim", "identifier", "gfrf")}

        def complete() -> bool:  # every node's status, the identifiers' with the final counts
            return health <= set(got["diag"]) and all(
                got["diag"][f"pmsm_sysid: {ns} identifier"]["values"]["windows_fitted"]
                == str(s["windows_fitted"]) for ns, s in ((ns_a, sa), (ns_b, sb)))

        _spin_both(a, b, complete)
        _spin_both(a, b, lambda: all(len(got[f"{ns}/{q}"]) >= 1 for ns in (ns_a, ns_b)
                                     for q in NUMBERS) and all(
            len(got[f"{ns}/stats/speed/terms"]) >= s["models_published"]
            for ns, s in ((ns_a, sa), (ns_b, sb))))
    assert sa["samples_received"] == sa["samples_published"] == 1000
    assert sb["samples_received"] == sb["samples_published"] == 1500
    for s in (sa, sb):
        assert s["duplicates"] == 0 and s["out_of_order"] == 0 and s["unaligned"] == 0
    assert sa["windows_fitted"] == sa["models_published"] >= 5
    assert sb["windows_fitted"] == sb["models_published"] >= 10
    ca, cb = a.nodes["collector"], b.nodes["collector"]
    assert ca.counts["model"] == sa["models_published"]
    assert cb.counts["model"] == sb["models_published"]
    assert a.gfrf.received == sa["models_published"]
    assert b.gfrf.received == sb["models_published"]
    # the seeds differ, so the two pipelines' models differ: nothing was shared
    last_a, last_b = sa["last_model"], sb["last_model"]
    assert last_a["terms"] != last_b["terms"]

    # /diagnostics: one status per node, grouped by name, the namespace as hardware id
    for ns, summ in ((ns_a, sa), (ns_b, sb)):
        ident = got["diag"][f"pmsm_sysid: {ns} identifier"]
        assert ident["hardware_id"] == ns and ident["level"] in (0, 1)
        v = ident["values"]
        assert int(v["samples_received"]) == summ["samples_received"]
        assert int(v["windows_skipped"]) == summ["windows_skipped"] == 0
        assert int(v["validation_pass"]) + int(v["validation_fail"]) >= 3
        assert {"input_rate_hz", "gaps", "change_events", "fit_latency_p50_ms"} <= set(v)
        # plottable numbers of this pipeline only: the last ones equal its last results
        assert got[f"{ns}/stats/speed/terms"][-1] == len(summ["last_model"]["terms"])
        assert got[f"{ns}/stats/speed/free_run_r2"][-1] == pytest.approx(
            summ["last_validation"]["free_run"]["r2"])
        peaks = summ["last_ridges"]["h1"]["peaks"]
        if peaks:
            top = max(peaks, key=lambda p: p["gain_db"])
            assert got[f"{ns}/stats/speed/h1_peak_hz"][-1] == pytest.approx(top["freq_hz"])
    assert len(got[f"{ns_a}/stats/speed/terms"]) == sa["models_published"]
    assert len(got[f"{ns_b}/stats/speed/terms"]) == sb["models_published"]


NUMBERS = ("stats/speed/terms", "stats/speed/free_run_r2", "stats/speed/free_run_nrmse",
           "stats/speed/change_statistic", "stats/speed/h1_peak_hz",
           "stats/speed/h1_peak_gain_db", "stats/speed/ridge_frequencies_hz")


def _listen(pipe: Any, *namespaces: str) -> dict[str, Any]:
    """A plain node on ``pipe``'s executor recording /diagnostics and the numbers."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64, Float64MultiArray, Int32

    from pmsm_sysid.nodes.monitor import diagnostic_dicts

    node = rclpy.create_node(f"listener_{uuid.uuid4().hex[:6]}", context=pipe.context)
    got: dict[str, Any] = {"diag": {}}

    def on_diag(msg: Any) -> None:
        for st in diagnostic_dicts(msg):
            got["diag"][st["name"]] = st

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 50)
    for ns in namespaces:
        for q in NUMBERS:
            cls = (Int32 if q.endswith("terms") else
                   Float64MultiArray if q.endswith("_hz") and "ridge" in q else Float64)
            got[f"{ns}/{q}"] = values = []
            node.create_subscription(cls, f"{ns}/{q}", lambda m, v=values: v.append(
                list(m.data) if isinstance(m, Float64MultiArray) else m.data), 100)
    pipe.executor.add_node(node)
    pipe.nodes["listener"] = node  # destroyed with the pipeline
    return got


def _spin_both(a: Any, b: Any, done: Any, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, "timed out"
        a.executor.spin_once(timeout_sec=0.02)
        b.executor.spin_once(timeout_sec=0.02)
