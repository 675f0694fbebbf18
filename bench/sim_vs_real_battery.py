"""Recording against recording: ``diagnose --sim`` on a simulator's and a real drive's recordings.

Both sides come from the independent integrator of ``battery_plant.py`` (its own RK4, friction
regularisation and noise streams; nothing shared with the project's simulator). The
"simulator" is a plant that is not the nominal motor (3.1 kg, 25 N s/m) recorded at 1 kHz
for 5 s, open loop (a chirp or a multisine plus a slow move); the "real" drive is recorded at
another rate (500 Hz, some at 250 Hz or 1 kHz) for 5 s, open loop or under a PID position
loop with the excitation injected into its output, at two noise levels, under four
excitations, each with a held-out recording of another seed (``--validate``). Kinds:

* controls -- the simulator's own physics recorded otherwise (excitation, loop, noise, rate;
  a strong process force; 2 N of thrust-reading noise; both sides with the same friction and
  cogging): right when ``effects`` and ``sim_only`` are empty (anything there, or a 'high'
  change, is a false alarm);
* the real drive has more -- each library effect concealed in the real recording (mass
  +13 %, viscous +20 %, Coulomb, Stribeck, cogging, ripple, offset, spring, a 1 ms lag, three
  at once, Coulomb stronger than the simulator's): right when each is in ``effects`` with its
  real value within tolerance (as the diagnose battery), nothing else at 'high', nothing in
  ``sim_only`` and the held-out force fit better;
* the simulation has more -- Coulomb, cogging or an offset only in the simulator: right when
  each is in ``sim_only`` with the simulator's value within tolerance, nothing at 'high' in
  ``effects`` and the held-out fit better;
* outside the library -- a local force bump, an actuator dead zone in the real drive: right
  when reported ``unexplained`` on the right axis with no library name at 'high'.

    python bench/sim_vs_real_battery.py [--jobs 2] [--only KIND ...] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from battery_plant import Case, Truth, record
from diagnose_battery import TOL, _unexplained_ok

from pmsm_sysid.core.discrepancy import DiagnoseOptions
from pmsm_sysid.core.discrepancy.against import diagnose_sim

SIM_FS, SIM_N = 1000.0, 5000
SIM = Truth(mass=3.1, viscous=25.0)
COG = (0.6, 0.007, 1.1)


@dataclass(frozen=True)
class Kind:
    """A kind of case: the two truths, what must be found, and the configurations."""

    role: str  # control | real | sim | outside
    sim: Truth
    real: Truth
    expect: dict[str, dict[str, float]] = field(default_factory=dict)
    configs: tuple[tuple[str, str, str, float], ...] = ()  # loop, excitation, noise, real fs
    sim_excitation: str = "chirp"
    axis: str = ""
    region: tuple[float, float] = (0.0, 0.0)


def _kinds() -> dict[str, Kind]:
    s = SIM
    mass, visc = 1.13 * s.mass, 1.2 * s.viscous
    return {
        "same": Kind("control", s, s, configs=(
            ("open", "prbs", "low", 500.0), ("open", "multisine", "high", 250.0),
            ("closed", "chirp", "low", 500.0), ("closed", "aprbs", "high", 500.0),
            ("closed", "prbs", "high", 1000.0))),
        "same_process_force": Kind("control", s, replace(s, process=4.0), configs=(
            ("open", "chirp", "high", 500.0), ("closed", "multisine", "low", 500.0))),
        "same_thrust_noise": Kind("control", s, replace(s, thrust_noise=2.0), configs=(
            ("open", "multisine", "low", 500.0), ("closed", "chirp", "high", 500.0)),
            sim_excitation="multisine"),
        "same_effects": Kind("control", replace(s, coulomb=2.0, cogging=COG),
                             replace(s, coulomb=2.0, cogging=COG), configs=(
            ("closed", "aprbs", "low", 500.0), ("open", "chirp", "high", 500.0)),
            sim_excitation="multisine"),
        "mass": Kind("real", s, replace(s, mass=mass), {"mass_error": {"mass_kg": mass}},
                     (("open", "chirp", "high", 500.0), ("closed", "multisine", "low", 500.0))),
        "viscous": Kind("real", s, replace(s, viscous=visc),
                        {"viscous_error": {"viscous_n_per_mps": visc}},
                        (("open", "aprbs", "low", 500.0), ("closed", "chirp", "high", 500.0))),
        "coulomb": Kind("real", s, replace(s, coulomb=2.5),
                        {"coulomb_friction": {"amplitude_n": 2.5}},
                        (("open", "multisine", "high", 500.0), ("closed", "prbs", "low", 500.0))),
        "stribeck": Kind("real", s, replace(s, coulomb=1.5, stribeck=2.0, stribeck_v=0.01),
                         {"coulomb_friction": {"amplitude_n": 1.5},
                          "stribeck_friction": {"static_n": 2.0}},
                         (("closed", "multisine", "high", 500.0),
                          ("closed", "chirp", "low", 500.0))),
        "cogging": Kind("real", s, replace(s, cogging=COG),
                        {"cogging": {"amplitude_n": 0.6, "pitch_m": 0.007}},
                        (("open", "multisine", "low", 500.0), ("closed", "aprbs", "high", 500.0))),
        "ripple": Kind("real", s, replace(s, ripple=(0.04, 0.024, 0.3)),
                       {"thrust_ripple": {"relative": 0.04, "pitch_m": 0.024}},
                       (("open", "prbs", "high", 500.0), ("open", "chirp", "low", 500.0))),
        "offset": Kind("real", s, replace(s, offset=1.5), {"force_offset": {"amplitude_n": 1.5}},
                       (("open", "chirp", "low", 500.0), ("closed", "prbs", "high", 500.0))),
        "spring": Kind("real", s, replace(s, spring=300.0),
                       {"spring": {"stiffness_n_per_m": 300.0}},
                       (("open", "multisine", "high", 500.0), ("closed", "aprbs", "low", 500.0))),
        "lag": Kind("real", s, replace(s, lag_s=0.001), {"thrust_lag": {"tau_s": 0.001}},
                    (("open", "prbs", "low", 500.0), ("open", "aprbs", "high", 500.0))),
        "three_at_once": Kind("real", s, replace(s, mass=mass, coulomb=2.0, cogging=COG),
                              {"mass_error": {"mass_kg": mass},
                               "coulomb_friction": {"amplitude_n": 2.0},
                               "cogging": {"amplitude_n": 0.6, "pitch_m": 0.007}},
                              (("closed", "chirp", "low", 500.0),
                               ("open", "multisine", "high", 500.0))),
        "coulomb_stronger": Kind("real", replace(s, coulomb=1.0), replace(s, coulomb=2.5),
                                 {"coulomb_friction": {"amplitude_n": 2.5}},
                                 (("open", "chirp", "low", 500.0),
                                  ("closed", "multisine", "high", 500.0)),
                                 sim_excitation="multisine"),
        "sim_coulomb": Kind("sim", replace(s, coulomb=2.0), s,
                            {"coulomb_friction": {"amplitude_n": 2.0}},
                            (("open", "multisine", "low", 500.0),
                             ("closed", "aprbs", "high", 500.0)), sim_excitation="multisine"),
        "sim_cogging": Kind("sim", replace(s, cogging=COG), s,
                            {"cogging": {"amplitude_n": 0.6, "pitch_m": 0.007}},
                            (("open", "chirp", "high", 500.0), ("closed", "prbs", "low", 500.0)),
                            sim_excitation="multisine"),
        "sim_offset": Kind("sim", replace(s, offset=1.5), s, {"force_offset": {"amplitude_n": 1.5}},
                           (("open", "aprbs", "low", 500.0), ("closed", "chirp", "high", 500.0))),
        "bump": Kind("outside", s, replace(s, bump=(0.5, 0.010, 0.003)), {},
                     (("open", "multisine", "high", 500.0), ("closed", "chirp", "low", 500.0)),
                     axis="position", region=(0.004, 0.016)),
        "dead_zone": Kind("outside", s, replace(s, dead_zone=1.5), {},
                          (("open", "aprbs", "low", 500.0), ("closed", "prbs", "high", 500.0)),
                          axis="thrust", region=(-1.5, 1.5)),
    }


KINDS = _kinds()


@dataclass(frozen=True)
class Item:
    """One case: kind, configuration and seed."""

    kind: str
    loop: str
    excitation: str
    noise: str
    fs: float
    seed: int

    @property
    def label(self) -> str:
        return f"{self.kind}/{self.loop}/{self.excitation}/{self.noise}/{self.fs:g}Hz/s{self.seed}"


def cases(only: list[str] | None = None) -> list[Item]:
    return [Item(k, *cfg, seed) for k, kind in KINDS.items() if not only or k in only
            for cfg in kind.configs for seed in (1, 2)]


def _rel(found: float, true: float) -> float:
    return abs(found - true) / abs(true)


def _param_errors(name: str, want: dict[str, float], got: dict[str, Any], closed: bool,
                  base: float) -> tuple[bool, list[str]]:
    """As the diagnose battery: relative errors, mass 3 % (5 % under a loop), viscous on the
    change; ``got`` holds absolute values (the real drive's, or the simulator's)."""
    ok, errs = True, []
    for key, true in want.items():
        if key not in got or got[key] is None:
            return False, [f"{name}.{key} missing"]
        err = _rel(float(got[key]), true)
        tol = 0.05 if (name == "mass_error" and closed) else TOL[key]
        if name == "viscous_error":
            err = _rel(float(got[key]) - base, true - base)
        ok &= err <= tol
        errs.append(f"{key.split('_')[0]} {100 * err:+.0f}%" if err < 10 else f"{key} off")
    return ok, errs


def _absolute(name: str, res: dict[str, Any], side: str) -> dict[str, Any]:
    """The absolute parameter values of effect ``name`` on ``side`` (real or sim): from the
    change rows (mass, viscous, additive effects) or from the effect's block."""
    out: dict[str, Any] = {}
    for c in res["changes"]:
        p = c["parameter"]
        if p in ("mass_kg", "viscous_n_per_mps") and name in ("mass_error", "viscous_error"):
            out[p] = c[side]
        elif p.startswith(name + "."):
            out[p.split(".", 1)[1]] = c[side]
    block = (res["real_plant"] if side == "real" else res["sim_plant"]).get(name) or {}
    for k, v in block.items():
        out.setdefault(k, v)
    return out


def judge(item: Item, res: dict[str, Any]) -> dict[str, Any]:
    kind = KINDS[item.kind]
    effects, only = res["effects"], res["sim_only"]
    named = [f"{e['name']}({e['confidence'][0]})" for e in effects]
    named_sim = [f"{e['name']}({e['confidence'][0]})" for e in only]
    val = res["fit"]["validation"]
    better = val["nrmse_after"] < val["nrmse_before"]
    high_changes = [c for c in res["changes"] if c["confidence"] == "high"]
    errs: list[str] = []
    if kind.role == "control":
        right = not effects and not only and not high_changes
    elif kind.role == "outside":
        wrong_high = [e for e in effects + only if e["name"] != "unexplained"
                      and e["confidence"] == "high"]
        case = Case(item.kind, kind.real, item.loop, item.excitation, item.noise, item.seed,
                    {}, kind.axis, kind.region)
        right = better and not wrong_high and _unexplained_ok(case, effects)
    else:
        listed, side = (effects, "real") if kind.role == "real" else (only, "sim")
        others = only if kind.role == "real" else effects
        right = better and not [e for e in others if e["confidence"] == "high"]
        for name, want in kind.expect.items():
            if not any(e["name"] == name for e in listed):
                right = False
                errs.append(f"{name} missed")
                continue
            base = kind.sim.viscous
            ok, e = _param_errors(name, want, _absolute(name, res, side), item.loop == "closed",
                                  base)
            right &= ok
            errs += e
        right &= not [e for e in listed if e["name"] not in kind.expect
                      and e["name"] != "unexplained" and e["confidence"] == "high"]
    return {"case": item.label, "kind": item.kind, "role": kind.role, "right": bool(right),
            "named": named, "sim_only": named_sim, "errors": errs,
            "changes": [f"{c['parameter']}({c['confidence'][0]})" for c in res["changes"]],
            "heldout": f"{val['nrmse_before']:.3f}->{val['nrmse_after']:.3f}",
            "false_alarm": kind.role == "control" and not right}


def run_case(item: Item) -> dict[str, Any]:
    kind = KINDS[item.kind]
    n = round(5.0 * item.fs)
    sim_case = Case(item.kind, kind.sim, "open", kind.sim_excitation, "low", item.seed)
    real_case = Case(item.kind, kind.real, item.loop, item.excitation, item.noise, item.seed)
    sim = record(sim_case, 50 + item.seed, SIM_FS, SIM_N)
    real = record(real_case, item.seed, item.fs, n)
    held = record(real_case, item.seed + 100, item.fs, n)
    t0 = time.perf_counter()
    try:
        res = diagnose_sim(sim, real, held, DiagnoseOptions(replay=False, gfrf=False))
    except Exception as exc:  # a case that fails is a wrong answer, not the end of the run
        return {"case": item.label, "kind": item.kind, "role": kind.role, "right": False,
                "named": [], "sim_only": [], "errors": [f"{type(exc).__name__}: {exc}"],
                "changes": [], "heldout": "-", "false_alarm": kind.role == "control",
                "seconds": time.perf_counter() - t0}
    out = judge(item, res.to_dict())
    out["seconds"] = time.perf_counter() - t0
    return out


def _md(rows: list[list[str]], head: list[str]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def confusion(results: list[dict[str, Any]]) -> str:
    """Reported (anything in effects or sim_only) against a difference being there."""
    cells: Counter[tuple[bool, bool]] = Counter()
    for r in results:
        cells[(r["role"] != "control", bool(r["named"] or r["sim_only"]))] += 1
    return _md([["difference there", str(cells[(True, True)]), str(cells[(True, False)])],
                ["same physics (controls)", str(cells[(False, True)]),
                 str(cells[(False, False)])]],
               ["truth \\ answer", "something reported", "nothing reported"])


def report(results: list[dict[str, Any]]) -> str:
    by_kind: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in results:
        by_kind[r["kind"]].append(r)
    rows = []
    for kind, rs in by_kind.items():
        eff = Counter(n for r in rs for n in r["named"])
        sim = Counter(n for r in rs for n in r["sim_only"])
        rows.append([kind, KINDS[kind].role, f"{sum(r['right'] for r in rs)}/{len(rs)}",
                     ", ".join(f"{n}×{c}" for n, c in eff.most_common()) or "-",
                     ", ".join(f"{n}×{c}" for n, c in sim.most_common()) or "-",
                     "; ".join(", ".join(r["errors"]) for r in rs if r["errors"]) or "-"])
    per_case = _md([[r["case"], "yes" if r["right"] else "NO", " ".join(r["named"]) or "-",
                     " ".join(r["sim_only"]) or "-", " ".join(r["changes"]) or "-",
                     ", ".join(r["errors"]) or "-", r["heldout"], f"{r['seconds']:.1f}"]
                    for r in results],
                   ["case", "right", "effects", "sim_only", "changes", "parameter errors",
                    "held-out force NRMSE", "s"])
    n_right = sum(r["right"] for r in results)
    controls = [r for r in results if r["role"] == "control"]
    fa = sum(r["false_alarm"] for r in controls)
    secs = sorted(r["seconds"] for r in results)
    summary = (f"right: {n_right}/{len(results)} = {100 * n_right / len(results):.1f} %; "
               f"false alarms: {fa}/{len(controls)} controls; time per case: median "
               f"{secs[len(secs) // 2]:.1f} s, at most {secs[-1]:.1f} s")
    return "\n\n".join([per_case, _md(rows, ["kind", "role", "right", "effects (real beyond "
                                             "sim)", "sim_only", "parameter errors"]),
                        confusion(results), summary])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    todo = cases(args.only)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(run_case, todo))
    print(report(results))
    print(f"{len(todo)} cases in {time.perf_counter() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
