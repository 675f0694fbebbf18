"""Two pipelines side by side on one domain: each lives in its own namespace.

Nodes are named under the namespace (``/a/pmsm_identifier``), every topic a pipeline creates
(inputs, models, ridges, ridge frequencies, validation, change events) lives under it, and
neither pipeline sees the other's samples or results.
"""

from __future__ import annotations

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
        # a runs first while b sits idle: with any cross-talk b's identifier would hold a's
        # samples, and a's collector b's models
        a.run(2.0)
        b.run(3.0)
        a.finish()
        b.finish()
        sa, sb = a.summary(), b.summary()
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
