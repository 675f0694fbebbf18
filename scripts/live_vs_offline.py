"""Check that the models a live run published equal offline ``identify`` on the same samples.

Usage: ``python scripts/live_vs_offline.py LIVE_BAG SOURCE_BAG`` where LIVE_BAG was written by
``pmsm-sysid run --nodes identifier,gfrf --record LIVE_BAG`` while ``pmsm-sysid replay
SOURCE_BAG`` played. Every model message of LIVE_BAG is identified again from SOURCE_BAG on
the window with the same stamps, with the same structure and method; the script prints how
many windows agree (same terms, estimates to ``--rtol``) and the largest relative difference,
and exits 1 if any does not.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

from pmsm_sysid.bagio import bag_topics, iter_raw, read_recording
from pmsm_sysid.bagio.common import typestore
from pmsm_sysid.core.selection.identify import FitConfig, identify_recording
from pmsm_sysid.core.terms.model import Structure


def live_models(path: str) -> list[dict[str, Any]]:
    """Every model JSON published on a ``.../model`` topic of the recording."""
    topics = [t for t, ty in bag_topics(path).items()
              if t.endswith("/model") and ty == "std_msgs/msg/String"]
    store = typestore()
    return [json.loads(store.deserialize_cdr(m.data, m.msgtype).data)
            for m in iter_raw(path, topics)]


def compare(model: dict[str, Any], rec: Any) -> tuple[bool, float]:
    """(same terms, largest relative difference of the estimates) against offline."""
    w = model["window"]
    a = int(np.searchsorted(rec.t, w["start_stamp"] - 1e-7))
    st = model["structure"]
    cfg = FitConfig(structure=Structure(st["ny"], st["nu"], st["degree"], st["delay"]),
                    n_terms=len(model["terms"]) - int(model.get("dc_removed", True)),
                    method=model["method"])
    ref = identify_recording(rec, output=model["output"], config=cfg,
                             estimate=(a, a + w["n_samples"]), validate=None,
                             form=model.get("form", "level")).to_dict()
    same = [t["name"] for t in model["terms"]] == [t["name"] for t in ref["terms"]]
    if not same:
        return False, float("inf")
    got = np.array([t["estimate"] for t in model["terms"]])
    want = np.array([t["estimate"] for t in ref["terms"]])
    return True, float(np.max(np.abs(got - want) / np.maximum(np.abs(want), 1e-300)))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("live")
    p.add_argument("source")
    p.add_argument("--rtol", type=float, default=1e-9)
    args = p.parse_args()
    rec = read_recording(args.source).recording
    models = live_models(args.live)
    worst, bad = 0.0, 0
    by_output: dict[str, int] = {}
    for m in models:
        same, rel = compare(m, rec)
        by_output[m["output"]] = by_output.get(m["output"], 0) + 1
        if not same or rel > args.rtol:
            bad += 1
            print(f"differs: {m['model_id']} (same terms: {same}, rel {rel:.3g})")
        worst = max(worst, rel)
    counts = ", ".join(f"{k} {v}" for k, v in sorted(by_output.items()))
    print(f"{len(models)} live models ({counts}); {len(models) - bad} equal offline identify "
          f"(same terms, estimates within {args.rtol:g}); largest relative difference "
          f"{worst:.2g}; speed derived: {rec.speed_derived}")
    return 1 if bad or not models else 0


if __name__ == "__main__":
    sys.exit(main())
