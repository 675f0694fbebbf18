"""Noise is not physics: ``diagnose`` on a nominal plant under every packaged excitation.

The control matrix of the sim-to-real diagnosis: the nominal motor of the paper's Table 1
simulated with the packaged simulator under each packaged excitation (paper-speed,
paper-position, multisine, chirp, prbs, aprbs, broadband), open loop and under a 15 Hz PID
position loop (±20 mm reference, the excitation injected into the loop's output at 6 N),
with several noises: the thrust reading's own noise (a thrust estimated from phase current:
1, 2, 5 and 10 N on top of 2 mm/s speed, 5 µm position noise and a 1 N process force),
high sensor noise without it, and a 4 N white process force. Each recording is diagnosed
against ``plants/nominal.yaml`` (held-out data: its last 30 %); a control is right when
nothing at all is named. Then the real effects under the same 5 N thrust noise: 13 % more
mass and a 1 ms actuator lag, which must still be found, with their parameters.

    python bench/diagnose_noise_controls.py [--jobs 2] [--seeds 7 3] [--duration 30]
        [--long] [--json out.json]

``--long`` adds 300 s recordings (the nominal and the cogging plant of the paper bags,
5 N thrust noise, multisine).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.physics.closed_loop import (
    PositionLoop,
    reference_trajectory,
    run_closed_loop,
)
from pmsm_sysid.core.physics.excitation import EXCITATIONS, make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import Noise, Plant, ThrustLag, nominal_plant

FS = 500.0
ROOT = Path(__file__).resolve().parent.parent
BASE = dict(speed_std=0.002, position_std=5e-6, force_std=1.0)
NOISES = {
    "thrust 1 N": Noise(**BASE, thrust_std=1.0),
    "thrust 2 N": Noise(**BASE, thrust_std=2.0),
    "thrust 5 N": Noise(**BASE, thrust_std=5.0),
    "thrust 10 N": Noise(**BASE, thrust_std=10.0),
    "sensors high": Noise(speed_std=0.005, position_std=1e-5, force_std=1.5),
    "process 4 N": Noise(speed_std=0.001, position_std=2e-6, force_std=4.0),
}
TRUTHS = {"mass +13%": {"mass_kg": 1.13 * 2.3213}, "lag 1 ms": {"tau_s": 0.001}}
TOL = {"mass_kg": 0.03, "tau_s": 0.30}


@dataclass(frozen=True)
class Run:
    """One recording: plant, drive, noise, seed and what must be found."""

    kind: str  # "control" | a TRUTHS key | "long"
    excitation: str
    loop: str
    noise: str
    seed: int
    duration: float
    plant_file: str = ""

    def plant(self) -> Plant:
        if self.plant_file:
            return Plant.from_yaml(ROOT / self.plant_file)
        p = nominal_plant().with_effects(noise=NOISES[self.noise])
        if self.kind == "mass +13%":
            p = dataclasses.replace(p, mass_kg=TRUTHS[self.kind]["mass_kg"])
        if self.kind == "lag 1 ms":
            p = p.with_effects(thrust_lag=ThrustLag(TRUTHS[self.kind]["tau_s"]))
        return p


def record(run: Run) -> Any:
    plant = run.plant()
    n = round(run.duration * FS)
    if run.loop == "open":
        return simulate(plant, make_excitation(run.excitation, n, FS, seed=run.seed),
                        seed=run.seed)
    ref = reference_trajectory(n, FS, (0.02, 0.004), (0.4, 1.7))
    inj = make_excitation(run.excitation, n, FS, seed=run.seed, amplitude_n=6.0)
    return run_closed_loop(plant, ref, PositionLoop.for_bandwidth(nominal_plant(), 15.0),
                           seed=run.seed, injection=inj)


def judge(run: Run) -> dict[str, Any]:
    t0 = time.perf_counter()
    rec = record(run)
    d = diagnose(nominal_plant(), rec, None, DiagnoseOptions(replay=False, gfrf=False))
    named = [(e.name, e.confidence) for e in d.effects]
    out: dict[str, Any] = {**dataclasses.asdict(run), "named": named,
                           "thrust_noise_n": d.method.get("thrust_reading", {}).get("noise_n"),
                           "seconds": time.perf_counter() - t0}
    if run.kind in TRUTHS:
        want = TRUTHS[run.kind]
        key, value = next(iter(want.items()))
        name = "mass_error" if key == "mass_kg" else "thrust_lag"
        got = next((e for e in d.effects if e.name == name), None)
        err = None if got is None else got.params[key] / value - 1.0
        others = [n for n, c in named if n != name and c == "high"]
        out["error"] = err
        out["right"] = err is not None and abs(err) <= TOL[key] and not others
    else:
        out["right"] = not named if run.kind == "control" else \
            not any(n not in ("cogging",) for n, _ in named)
    return out


def runs(seeds: Sequence[int], duration: float, long: bool) -> list[Run]:
    out = [Run("control", exc, loop, noise, seed, duration)
           for noise in NOISES for loop in ("open", "closed") for exc in EXCITATIONS
           for seed in seeds]
    out += [Run(kind, exc, "open", "thrust 5 N", seed, duration)
            for kind in TRUTHS for exc in ("multisine", "chirp", "paper-speed")
            for seed in seeds]
    if long:
        out += [Run("long", "multisine", "open", "thrust 5 N", 7, 300.0,
                    "plants/nominal_noisy.yaml"),
                Run("long", "multisine", "open", "thrust 5 N", 7, 300.0,
                    "plants/cogging.yaml")]
    return out


def _names(rows: list[dict[str, Any]]) -> str:
    names = sorted({f"{n}({c[0]})" for r in rows for n, c in r["named"]})
    return " ".join(names)


def report(results: list[dict[str, Any]]) -> str:
    lines = ["| noise | loop | " + " | ".join(EXCITATIONS) + " |",
             "|---|---|" + "---|" * len(EXCITATIONS)]
    controls = [r for r in results if r["kind"] == "control"]
    for noise in NOISES:
        for loop in ("open", "closed"):
            cells = []
            for exc in EXCITATIONS:
                rows = [r for r in controls if (r["noise"], r["loop"], r["excitation"])
                        == (noise, loop, exc)]
                bad = [r for r in rows if not r["right"]]
                cell = f"{len(rows) - len(bad)}/{len(rows)}"
                cells.append(cell + (f" {_names(bad)}" if bad else ""))
            lines.append(f"| {noise} | {loop} | " + " | ".join(cells) + " |")
    lines += ["", "| truth (5 N thrust noise) | excitation | seed | found | error |",
              "|---|---|---|---|---|"]
    for r in results:
        if r["kind"] in TRUTHS:
            err = "missed" if r["error"] is None else f"{r['error']:+.1%}"
            lines.append(f"| {r['kind']} | {r['excitation']} | {r['seed']} | "
                         f"{_names([r]) or '-'} | {err} |")
    for r in results:
        if r["kind"] == "long":
            lines.append(f"\n{r['plant_file']} {r['excitation']} {r['duration']:.0f} s: "
                         f"{_names([r]) or 'nothing'} ({r['seconds']:.0f} s)")
    right_c = sum(r["right"] for r in controls)
    truths = [r for r in results if r["kind"] in TRUTHS]
    lines.append(f"\ncontrols silent: {right_c}/{len(controls)}; real effects found: "
                 f"{sum(r['right'] for r in truths)}/{len(truths)}; diagnose "
                 f"{max(r['seconds'] for r in results):.1f} s at most")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seeds", type=int, nargs="+", default=[7, 3])
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--long", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    todo = runs(args.seeds, args.duration, args.long)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(judge, todo))
    print(report(results))
    print(f"{len(results)} recordings in {time.perf_counter() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    main()
