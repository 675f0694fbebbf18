"""The live diagnosis for a simulated hour: how often does it name physics that is not there?

The spans go through the diagnosis node's own data path, without ROS: the simulated motor
stepped sample by sample as the sim node does, the window ring the node cuts its spans with
(:func:`~pmsm_sysid.core.online.livesim.simulated_windows`, the node's defaults: the latest
30 s every 10 s), and the node's worker (:class:`~pmsm_sysid.nodes.diagnosis_work.
LiveDiagnoser`, ``ps.diagnose`` with the node's default options, the last 30 % of each span
held out): what ``pmsm-sysid run --clock sim --diagnose plants/nominal.yaml`` diagnoses when
no span is skipped (``test/test_live_diagnosis.py`` checks that a live span equals the
offline one, sample for sample, and that its diagnosis is the same). Deterministic; the spans
are diagnosed ``--jobs`` at a time.

The drive is the default plant ``drive`` (the paper's Table 1 motor as a 1 um scale measures
it, with a 1 N white process force) under the default broadband excitation, diagnosed
against ``plants/nominal.yaml``: every span that names anything is a false alarm (the
drive's noise is not physics).

``--switch coulomb|cogging``: a 2 N Coulomb friction (or a 1 N cogging at 5 mm) switched on
after ``--minutes``; four more periods follow. Prints what each span after the switch names
and its values against the truth.

    .venv/bin/python bench/live_diagnosis_bench.py [--minutes 60] [--seed 0] [--jobs 2]
                                                   [--switch coulomb|cogging] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from pmsm_sysid import diagnosed
from pmsm_sysid.core.online.livesim import simulated_windows
from pmsm_sysid.core.online.windows import Window
from pmsm_sysid.core.physics.plant import Cogging, CoulombFriction, load_plant
from pmsm_sysid.nodes.diagnosis_node import DEFAULTS
from pmsm_sysid.nodes.diagnosis_work import DiagnoseJob, LiveDiagnoser

FS = 500.0
SWITCHES = {"coulomb": {"coulomb_friction": CoulombFriction(2.0)},
            "cogging": {"cogging": Cogging(1.0, 0.005, 0.5)}}
TRUTH = {"coulomb": {"coulomb_friction/amplitude_n": 2.0},
         "cogging": {"cogging/amplitude_n": 1.0, "cogging/pitch_m": 0.005}}
_worker: dict[str, Any] = {}


def _diagnose(w: Window) -> dict[str, Any]:
    if "d" not in _worker:
        _worker["d"] = LiveDiagnoser(load_plant("plants/nominal.yaml"), "plants/nominal.yaml")
    c0 = time.process_time()
    opts = {k: DEFAULTS[k] for k in ("alpha", "min_share", "replay", "gfrf")}
    d = _worker["d"](DiagnoseJob(w, FS, **opts))
    return {"t": w.end_stamp + 1 / FS, "effects": [dict(e) for e in d["effects"]],
            "numbers": {k: v for k, v in diagnosed.numbers(d).items() if v == v},
            "cpu_s": time.process_time() - c0}


def spans(minutes: float, seed: int, switch: str | None) -> Iterator[Window]:
    drive = load_plant("drive")
    k_on = round(60.0 * minutes * FS)
    period_s, span_s = float(DEFAULTS["period_s"]), float(DEFAULTS["span_s"])
    n = k_on + (round(4 * period_s * FS) if switch else 0)
    change = {k_on: drive.with_effects(**SWITCHES[switch])} if switch else None
    yield from simulated_windows(drive, "broadband", n, window=round(span_s * FS),
                                 hop=round(period_s * FS), history=0, seed=seed, switch=change)


def run(minutes: float, seed: int, switch: str | None, jobs: int) -> dict[str, Any]:
    t0 = time.monotonic()
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        rows = list(pool.map(_diagnose, spans(minutes, seed, switch)))
    return {"minutes": minutes, "seed": seed, "switch": switch, "rows": rows,
            "t_on": 60.0 * minutes if switch else None, "wall_s": time.monotonic() - t0,
            "span_s": DEFAULTS["span_s"], "period_s": DEFAULTS["period_s"]}


def report(r: dict[str, Any]) -> None:
    rows, t_on = r["rows"], r["t_on"]
    quiet = [x for x in rows if t_on is None or x["t"] <= t_on]
    named = [x for x in quiet if x["effects"]]
    cpu = sum(x["cpu_s"] for x in rows) / max(len(rows), 1)
    print(f"plant drive vs plants/nominal.yaml, broadband, seed {r['seed']}, "
          f"{r['minutes']:g} simulated minutes, {r['span_s']:g} s spans every "
          f"{r['period_s']:g} s: {len(rows)} diagnoses, {cpu:.1f} s CPU each, "
          f"{r['wall_s']:.0f} s wall")
    print(f"diagnoses of the stationary nominal drive that named something: {len(named)} of "
          f"{len(quiet)}")
    kinds = Counter(f"{e['name']} ({e['confidence']})" for x in named for e in x["effects"])
    for name, n in kinds.most_common():
        print(f"  {name}: {n}")
    for x in named:
        print(f"  t={x['t']:.0f} s: " + ", ".join(diagnosed.effect_text(e)
                                                 for e in x["effects"]))
    if t_on is None:
        return
    print(f"{r['switch']} switched on at t={t_on:g} s:")
    for x in rows:
        if x["t"] > t_on:
            k = round((x["t"] - t_on) / r["period_s"])
            found = ", ".join(diagnosed.effect_text(e) for e in x["effects"]) or "nothing"
            values = {q: round(x["numbers"][q], 5) for q in TRUTH[r["switch"]]
                      if q in x["numbers"]}
            print(f"  {k} period(s) after: {found}; {values} (truth {TRUTH[r['switch']]})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--switch", choices=sorted(SWITCHES))
    ap.add_argument("--json", metavar="FILE")
    a = ap.parse_args(argv)
    r = run(a.minutes, a.seed, a.switch, a.jobs)
    report(r)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(r, f, indent=1)
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
