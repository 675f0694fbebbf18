"""Long recordings keep the statistics honest: controls name nothing, concealed effects are found.

A recording longer than the sample budget is diagnosed on ten spans spread over it (see
``docs/diagnose.md``, *Long recordings*). This runs what must hold at any length:

* **controls** -- the nominal motor with the noise real drives have (speed 2 mm/s,
  position 5 um, process force 1 N, 1 um encoder; one case with 5 N of thrust-reading
  noise), open loop (the paper's position excitation; a multisine with a slow positioning
  move; a PRBS) and under a 15 Hz PID position loop, simulated for 600 s and 3600 s at
  500 Hz, and the independent simulator of the diagnose battery (``battery_plant.py``:
  its own integration, friction regularisation and noise streams) for 600 s: nothing may
  be named;
* **concealed effects** -- the plants of ``bags/concealed_*`` (cogging 0.6 N at 7 mm;
  Coulomb 2.5 N + Stribeck 1.5 N under a loop; the winding lag 0.41 ms; cogging 1 N at
  6 mm with Coulomb 2 N under a loop) simulated for 600 s: each true effect named with its
  parameters within the scenarios' tolerances (pitch 2 %, amplitudes 20 %, Coulomb 10 %,
  lag 25 %), nothing else at 'high';
* **a slow disturbance** -- a 0.5 N force with a period of a quarter of the recording
  (150 s in 600 s), open loop, from the battery's simulator: reported as ``unexplained``
  over time at its frequency (within 5 %), which only spans spread over the whole
  recording can show.

    python bench/diagnose_long_checks.py [--lengths 600,3600] [--only NAME ...] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import battery_plant as bp

from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.discrepancy.scenarios import (
    FS,
    NOISE,
    QUANT,
    SCENARIOS,
    TRUTH_TOLERANCE,
    make_recording,
)
from pmsm_sysid.core.physics.closed_loop import PositionLoop, reference_trajectory, run_closed_loop
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import nominal_plant
from pmsm_sysid.core.recording.signals import Recording

TOL = TRUTH_TOLERANCE
CONTROLS = ("paper_position", "multisine", "prbs_thrust_noise", "loop")
BATTERY = (("nominal", "open", "prbs", "low"), ("nominal", "closed", "chirp", "low"),
           ("process_noise", "closed", "aprbs", "low"))
CONCEALED = ("cogging", "friction", "lag", "two")
SLOW_PERIOD_FRACTION = 0.25  # of the recording


def _noisy(thrust_std: float = 0.0) -> Any:
    noise = replace(NOISE, thrust_std=thrust_std)
    return nominal_plant().with_effects(noise=noise, quantisation=QUANT)


def control(kind: str, seconds: float, seed: int) -> Recording:
    """One control recording of the project's simulator (module doc)."""
    n = round(seconds * FS)
    t = np.arange(n) / FS
    if kind == "paper_position":
        return simulate(_noisy(), make_excitation("paper-position", n, FS, seed=seed), seed=seed)
    if kind == "multisine":
        u = make_excitation("multisine", n, FS, seed=seed) + 3.0 * np.cos(2 * np.pi * 0.5 * t)
        return simulate(_noisy(), u, seed=seed)
    if kind == "prbs_thrust_noise":
        return simulate(_noisy(5.0), make_excitation("prbs", n, FS, seed=seed), seed=seed)
    ref = reference_trajectory(n, FS, (0.02, 0.004), (0.4, 1.7))
    return run_closed_loop(_noisy(), ref, PositionLoop.for_bandwidth(nominal_plant(), 15.0),
                           seed=seed)


def battery(kind: str, loop: str, excitation: str, noise: str, seconds: float,
            seed: int) -> Recording:
    """A case of the battery's independent simulator, ``seconds`` long."""
    truth = bp.Truth(process=4.0) if kind == "process_noise" else bp.Truth()
    if kind == "slow":
        truth = bp.Truth(periodic=(0.5, 1.0 / (SLOW_PERIOD_FRACTION * seconds)))
    bp.N = round(seconds * bp.FS)  # the battery simulates N samples
    return bp.record(bp.Case(kind, truth, loop, excitation, noise, seed), seed)


def _named(result: Any) -> dict[str, Any]:
    return {e.name: e for e in result.effects}


def _close(value: float, truth: float, tol: float) -> bool:
    return abs(value - truth) <= tol * abs(truth)


def concealed_ok(name: str, found: dict[str, Any]) -> tuple[bool, str]:
    """Every true effect named within tolerance, nothing else at 'high'."""
    plant = SCENARIOS[name].plant
    want: dict[str, bool] = {}
    if plant.cogging is not None:
        e = found.get("cogging")
        want["cogging"] = e is not None and _close(e.params["pitch_m"], plant.cogging.pitch_m,
                                                   TOL["pitch_m"]) \
            and _close(e.params["amplitude_n"], plant.cogging.amplitude_n, TOL["amplitude_n"])
    if plant.coulomb_friction is not None:
        e = found.get("coulomb_friction")
        want["coulomb_friction"] = e is not None and _close(
            e.params["amplitude_n"], plant.coulomb_friction.amplitude_n, TOL["coulomb"])
    if plant.thrust_lag is not None:
        e = found.get("thrust_lag") or found.get("transport_delay")
        value = None if e is None else e.params.get("tau_s", e.params.get("delay_s"))
        want["thrust_lag"] = value is not None and _close(value, plant.thrust_lag.tau_s,
                                                          TOL["tau_s"])
    extra = [n for n, e in found.items() if n not in want and e.confidence == "high"
             and n not in ("stribeck_friction", "transport_delay")]
    ok = all(want.values()) and not extra
    why = ", ".join(f"{k} {'ok' if v else 'MISSED/OFF'}" for k, v in want.items())
    return ok, why + (f"; extra at high: {', '.join(extra)}" if extra else "")


def slow_ok(found: dict[str, Any], seconds: float) -> tuple[bool, str]:
    """An ``unexplained`` force over time at the disturbance's frequency, no library name."""
    f0 = 1.0 / (SLOW_PERIOD_FRACTION * seconds)
    e = found.get("unexplained")
    f = None if e is None else e.params.get("frequency_hz")
    ok = f is not None and abs(f - f0) <= 0.05 * f0 and set(found) == {"unexplained"}
    return ok, f"sinusoid over time at {f0:.4g} Hz: " + ("found at " f"{f:.4g} Hz"
                                                           if f else "MISSED")


def run_case(case: tuple[str, str, float]) -> dict[str, Any]:
    group, name, seconds = case
    t0 = time.process_time()
    if group == "control":
        rec = control(name, seconds, seed=11)
    elif group == "battery":
        kind, loop, exc, noise = name.split("/")
        rec = battery(kind, loop, exc, noise, seconds, seed=11)
    else:
        rec = make_recording(name, seed=11, duration_s=seconds)
    sim_s = time.process_time() - t0
    t0 = time.process_time()
    result = diagnose(nominal_plant(), rec, options=DiagnoseOptions(gfrf=False))
    found = _named(result)
    if group == "concealed":
        ok, why = concealed_ok(name, found)
    elif name.startswith("slow"):
        ok, why = slow_ok(found, seconds)
    else:
        ok, why = not found, "nothing named" if not found else "FALSE ALARM"
    used = result.method["data_used"]["recording"]
    return {"group": group, "name": name, "seconds": seconds, "ok": ok, "why": why,
            "found": [f"{e.name}({e.confidence[0]})" + _params(e) for e in result.effects],
            "used": f"{used['samples']} of {used['of_samples']}",
            "sim_cpu_s": sim_s, "diagnose_cpu_s": time.process_time() - t0}


def _params(e: Any) -> str:
    keys = ("amplitude_n", "pitch_m", "tau_s", "delay_s", "static_n", "frequency_hz", "axis")
    shown = [f"{k}={e.params[k]:.4g}" if isinstance(e.params[k], float)
             else f"{k}={e.params[k]}" for k in keys if k in e.params]
    return f" [{', '.join(shown)}]" if shown else ""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lengths", default="600,3600",
                    help="seconds for the controls of the project's simulator")
    ap.add_argument("--concealed-length", type=float, default=600.0)
    ap.add_argument("--battery-length", type=float, default=600.0)
    ap.add_argument("--only", nargs="*", default=None, help="case names to run")
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args()
    cases = [("control", k, float(s)) for s in args.lengths.split(",") for k in CONTROLS]
    cases += [("battery", "/".join(b), args.battery_length) for b in BATTERY]
    cases += [("concealed", k, args.concealed_length) for k in CONCEALED]
    cases += [("battery", "slow/open/multisine/low", args.battery_length)]
    if args.only:
        cases = [c for c in cases if c[1] in args.only]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run_case, cases))
    print("| group | case | length | used | found | right |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['group']} | {r['name']} | {r['seconds']:g} s | {r['used']} | "
              f"{'; '.join(r['found']) or 'nothing'} | {'yes' if r['ok'] else 'NO'}: "
              f"{r['why']} |")
    wrong = [r for r in rows if not r["ok"]]
    print(f"\n{len(rows) - len(wrong)} of {len(rows)} right")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
