"""How often the cross-validation of a correct model fails a window, and what the run verdict
makes of it: simulated data of the ``run`` defaults through the identifier's own data path.

``--duration`` seconds (default 600) of the default plant (``drive``) under the default
excitation (``broadband``, or ``--excitation``) go through the window ring and the
:class:`~pmsm_sysid.core.online.tracker.WindowTracker` with the identifier node's defaults,
as ``pmsm-sysid run --clock sim`` does with no window skipped. Per output it prints the
windows that failed their cross-validation (and which correlation test), the failure rate
beside the rate the tests' own rule gives for white residuals
(:func:`~pmsm_sysid.core.validation.correlation.window_false_rejection_rate`), how many
failed windows have a failed neighbour (the windows overlap: the outcomes of neighbouring
windows are not independent), and the share of runs of 10, 30 and 60 s whose verdict is not
``pass`` (:func:`pmsm_sysid.cli.run_verdict.window_rate`): the verdict's false alarms on a
correct model. ``--set speed.terms=3`` etc. changes an identifier parameter (a model too
small for the plant shows what a wrong structure does). Deterministic.

``--phases N`` cuts the same simulated samples on N window grids, their sample index shifted
by offsets spread evenly over the hop (what the epoch-derived index of a wall-clock run
does), each through a fresh tracker; the counts above are then over all grids. Per output it
adds the correlation rho(d) of two windows' outcomes (failed = 1) at a shift of d windows
(start difference / window length, d = 0.05 ... 3.0) over all windows of all grids, each
paired with the window starting nearest to d later if within half a step of d ("n/a": too
few are, e.g. below the hop with one grid); and per run length the dispersion of the failed
count over the runs (its variance / the binomial variance at the runs' failure rate) beside
the dispersion phi(n, s) = 1 + (2/n) sum_{k=1}^{n-1} (n - k) rho(k s) that this rho gives
(s = hop / window, rho linear between its shifts, 0 beyond 3 windows), the dispersion the
verdict assumes (:func:`pmsm_sysid.core.validation.windows.dispersion`, from its table of rho)
and the share of runs not judged pass. Runs of different grids share their data, so they
are not independent runs.

    .venv/bin/python bench/validation_rate.py [--duration 600] [--excitation broadband]
                                              [--set position.terms=2] [--phases 20]
                                              [--json FILE]
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from collections.abc import Iterable
from typing import Any

import numpy as np
import yaml

from pmsm_sysid.cli.run_verdict import NULL_RATE, window_rate
from pmsm_sysid.core.online.livesim import simulated_samples
from pmsm_sysid.core.online.streaming import Sample
from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config
from pmsm_sysid.core.online.windows import WindowScheduler
from pmsm_sysid.core.physics.plant import load_plant
from pmsm_sysid.core.validation.correlation import window_false_rejection_rate
from pmsm_sysid.core.validation.windows import dispersion as verdict_dispersion
from pmsm_sysid.nodes.identifier_node import DEFAULTS

RUNS_S = (10, 30, 60)
#: Seconds at the start of a CLI run that give no validated window (8 hops of 250 samples).
LOST_S = 4.0
#: Shifts of rho(d), in windows.
SHIFTS = tuple(round(0.05 * k, 2) for k in range(1, 61))
#: rho(d) needs this share of the windows to have a partner d windows later.
MIN_PAIRED = 0.2

Rows = list[dict[str, Any]]


def _params(settings: list[str]) -> dict[str, Any]:
    params = dict(DEFAULTS)
    for item in settings:
        key, _, value = item.partition("=")
        params[key] = yaml.safe_load(value)
    return params


def _offsets(hop: int, phases: int) -> list[int]:
    """Shifts of the sample index, spread evenly over the hop."""
    return sorted({round(j * hop / phases) for j in range(phases)})


def _grid(samples: Iterable[Sample], params: dict[str, Any], offset: int) -> dict[str, Rows]:
    """Each output's validated windows, cut with the sample index shifted by ``offset``;
    ``start``: the sample (of the simulation) its model's window starts at."""
    tracker = WindowTracker(tracker_config(params))
    ring = WindowScheduler(tracker.config.window, tracker.config.hop, tracker.history)
    out: dict[str, Rows] = collections.defaultdict(list)
    for s in samples:
        w = ring.push(Sample(s.index + offset, s.stamp_ns, s.values))
        if w is None:
            continue
        for v in tracker.process(w).validations:
            out[v["output"]].append({
                "start": v["model_window"]["start_index"] - offset, "pass": bool(v["pass"]),
                "r2": v["free_run"]["r2"],
                "failed": [k for k, t in v["correlation_tests"].items() if not t["pass"]]})
    return out


def _outcomes(args: argparse.Namespace, params: dict[str, Any]) -> dict[str, list[Rows]]:
    """Each output's windows, one list per grid offset (one grid without ``--phases``)."""
    plant = load_plant(args.plant)
    n = round(args.duration * plant.sample_rate_hz)
    samples: Iterable[Sample] = simulated_samples(plant, args.excitation, n, seed=args.seed)
    offsets = _offsets(int(params["hop"]), args.phases or 1)
    if len(offsets) > 1:
        samples = list(samples)
    out: dict[str, list[Rows]] = collections.defaultdict(list)
    for offset in offsets:
        for output, rows in _grid(samples, params, offset).items():
            out[output].append(rows)
    return out


def _runs(seqs: list[list[bool]], per_run: int, shift: float) -> dict[str, Any]:
    """Consecutive runs of ``per_run`` windows (``shift``: hop / window) of each grid: how
    many the verdict does not judge consistent with a correct model, and the dispersion of
    their failed count."""
    failed, flagged = [], 0
    for seq in seqs:
        for k in range(0, len(seq) - per_run + 1, per_run):
            chunk = seq[k:k + per_run]
            failed.append(per_run - sum(chunk))
            flagged += not window_rate(sum(chunk), per_run, shift=shift)["consistent"]
    rate = sum(failed) / max(1, len(failed) * per_run)
    dispersion = (float(np.var(failed, ddof=1)) / (per_run * rate * (1 - rate))
                  if len(failed) > 1 and 0 < rate < 1 else None)
    return {"windows": per_run, "runs": len(failed), "not_pass": flagged,
            "dispersion": dispersion, "verdict_phi": verdict_dispersion(per_run, shift)}


def _rho(grids: list[Rows], window: int) -> dict[float, float | None]:
    """rho(d) of the outcomes (failed = 1) of windows d windows apart, over all grids; each
    window paired with the window starting nearest to d later, if within half a step of d."""
    start = np.array([r["start"] for rows in grids for r in rows], dtype=np.int64)
    x = np.array([not r["pass"] for rows in grids for r in rows], dtype=float)
    order = np.argsort(start, kind="stable")
    start, x = start[order], x[order]
    rate = x.mean() if len(x) else 0.0
    out: dict[float, float | None] = dict.fromkeys(SHIFTS)
    if not 0 < rate < 1:
        return out
    tol = (SHIFTS[1] - SHIFTS[0]) * window / 2
    for d in SHIFTS:
        target = start + d * window
        j = np.clip(np.searchsorted(start, target), 1, len(start) - 1)
        j -= np.abs(start[j - 1] - target) < np.abs(start[j] - target)
        ok = np.abs(start[j] - target) <= tol
        if ok.sum() >= max(2, MIN_PAIRED * len(start)):
            cov = np.mean((x[ok] - rate) * (x[j[ok]] - rate))
            out[d] = float(cov / (rate * (1 - rate)))
    return out


def phi(rho: dict[float, float | None], n: int, s: float) -> float | None:
    """Dispersion of the failed count of ``n`` windows ``s`` windows apart whose outcomes
    correlate by ``rho`` (linear between its shifts, 0 beyond the last)."""
    known = [(d, r) for d, r in sorted(rho.items()) if r is not None]
    return verdict_dispersion(n, s, table=known) if known else None


def _output(grids: list[Rows], params: dict[str, Any], hop_s: float,
            phases: bool) -> dict[str, Any]:
    """One output's counts over its grids (with ``phases``: rho, dispersion and phi too)."""
    seqs = [[r["pass"] for r in rows] for rows in grids]
    failed = [{i for i, ok in enumerate(seq) if not ok} for seq in seqs]
    paired = sum(1 for f in failed for i in f if {i - 1, i + 1} & f)
    tests = collections.Counter(t for rows in grids for r in rows for t in r["failed"])
    shift = int(params["hop"]) / int(params["window"])
    runs = {f"{s} s": _runs(seqs, max(1, round((s - LOST_S) / hop_s)), shift)
            for s in RUNS_S}
    res: dict[str, Any] = {
        "windows": sum(map(len, seqs)), "failed": sum(map(len, failed)),
        "with_failed_neighbour": paired, "tests": dict(tests),
        "runs_not_pass": {k: [r["not_pass"], r["runs"]] for k, r in runs.items()}}
    if phases:
        window, hop = int(params["window"]), int(params["hop"])
        rho = _rho(grids, window)
        for r in runs.values():
            r["phi"] = phi(rho, r["windows"], hop / window)
        res.update(rho={str(d): r for d, r in rho.items()}, runs=runs,
                   grids=[[[r["start"], r["pass"]] for r in rows] for rows in grids])
    return res


def _num(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}"


def _print(output: str, res: dict[str, Any]) -> None:
    n, f = res["windows"], res["failed"]
    print(f"  {output}: {f}/{n} windows failed ({100 * f / max(n, 1):.2f} %; {res['tests']}), "
          f"{res['with_failed_neighbour']} of them beside another failed one; runs not judged "
          "pass: " + ", ".join(f"{k} {a}/{b}" for k, (a, b) in res["runs_not_pass"].items()))
    if "rho" not in res:
        return
    rho = list(res["rho"].items())
    for i in range(0, len(rho), 10):
        print(f"    rho(d), d = {rho[i][0]}..{rho[min(i + 9, len(rho) - 1)][0]} windows: "
              + " ".join("  n/a" if r is None else f"{r:+.2f}" for _, r in rho[i:i + 10]))
    for k, r in res["runs"].items():
        share = 100 * r["not_pass"] / max(1, r["runs"])
        print(f"    runs of {k} ({r['windows']} windows): dispersion {_num(r['dispersion'])} "
              f"(phi from rho {_num(r['phi'])}, the verdict's {_num(r['verdict_phi'])}), "
              f"not pass {r['not_pass']}/{r['runs']} "
              f"= {share:.1f} %")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--plant", default="drive")
    p.add_argument("--excitation", default="broadband")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE")
    p.add_argument("--phases", type=int, default=None, metavar="N",
                   help="window grids, shifted by offsets spread over the hop")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    params = _params(args.set)
    hop_s = int(params["hop"]) / load_plant(args.plant).sample_rate_hz
    result: dict[str, Any] = {"derived_rate": window_false_rejection_rate(),
                              "null_rate": NULL_RATE, "outputs": {}}
    grids = "" if args.phases is None else f", {args.phases} grid offset(s)"
    print(f"{args.plant}, {args.excitation}, {args.duration:g} s{grids}, {' '.join(args.set)}; "
          f"rate of the tests' rule for white residuals "
          f"{100 * result['derived_rate']:.2f} %, the verdict allows {100 * NULL_RATE:g} %")
    for output, rows in _outcomes(args, params).items():
        res = _output(rows, params, hop_s, args.phases is not None)
        result["outputs"][output] = res
        _print(output, res)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
