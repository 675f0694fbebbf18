"""``pmsm-sysid identify BAG``: offline NARX identification by OFR on one recording.

Defaults reproduce the paper's speed case: thrust -> speed, ny = 30, nu = 40, quadratic,
15 terms, estimation samples 1000:2000 and validation 3000:4000 (the paper's points
1001-2000 and 3001-4000). ``--output position --ny 10 --nu 10`` is the paper's second case.
Prints the term table in the layout of the paper's Tables 2 and 3 (term, estimate, standard
deviation, ERR) and the validation summary; ``--json FILE`` writes the identify JSON.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from .common import count, parse_fraction, parse_range, ros_name, write_json

HELP = "offline NARX identification by OFR on one recording"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file"}


#: Largest lag (and delay) asked for: 20 s of a 500 Hz recording.
MAX_LAG = 10_000


def add_model_options(p: Any) -> None:
    """The model and protocol options shared by ``identify`` and ``report`` (a parser or an
    argument group)."""
    p.add_argument("--input", default="thrust", choices=("thrust",), help="input signal")
    p.add_argument("--output", default="speed", choices=("speed", "position"),
                   help="output signal (default speed)")
    p.add_argument("--form", choices=("level", "difference"), default="level",
                   help="model the output as measured (level, the paper's protocol) or as its "
                        "increment per sample y(k)-y(k-1) (difference: the bounded form of an "
                        "integrating output such as position; the live identifier's default "
                        "for position)")
    p.add_argument("--ny", type=count(0, MAX_LAG), default=30,
                   help="output lags y(k-1..k-ny) (default 30)")
    p.add_argument("--nu", type=count(0, MAX_LAG), default=40,
                   help="input lags u(k-d..k-d-nu+1) (default 40)")
    p.add_argument("--degree", type=int, choices=(1, 2, 3), default=2,
                   help="polynomial degree (default 2)")
    p.add_argument("--terms", type=count(1, 10_000), default=15,
                   help="number of terms, or the maximum for --criterion err/aic/bic (default 15)")
    p.add_argument("--delay", type=count(0, MAX_LAG), default=1, help="input delay d (default 1)")
    p.add_argument("--estimate", type=parse_range, default=(1000, 2000), metavar="START:STOP",
                   help="estimation samples, 0-based half-open (default 1000:2000)")
    p.add_argument("--validate", type=parse_range, default=(3000, 4000), metavar="START:STOP",
                   help="validation samples (default 3000:4000)")
    p.add_argument("--no-validate", action="store_true", help="skip the validation window")
    p.add_argument("--criterion", choices=("terms", "err", "aic", "bic"), default="terms",
                   help="model size: fixed --terms, 1-sum(ERR) < rho, or AIC/BIC (default terms)")
    p.add_argument("--rho", type=parse_fraction, default=1e-3,
                   help="ERR tolerance for --criterion err")
    p.add_argument("--method", choices=("iofr", "ofr"), default="iofr",
                   help="iofr: FROLS refined by exact term exchange (default); ofr: classic FROLS")
    p.add_argument("--no-constant", action="store_true",
                   help="no constant candidate (then the d.c. level is not removed in ERR)")
    p.add_argument("--keep-dc", action="store_true",
                   help="ERR on the raw output (Billings/SysIdentPy convention), constant as an "
                        "ordinary candidate")
    p.add_argument("--corr-lags", type=count(1, MAX_LAG), default=20,
                   help="lags of the correlation tests (default 20)")


def fit_config(args: argparse.Namespace) -> Any:
    """The FitConfig the options of :func:`add_model_options` ask for."""
    from ..api.identification import fit_config as config

    return config(ny=args.ny, nu=args.nu, degree=args.degree, terms=args.terms,
                  delay=args.delay, criterion=args.criterion, rho=args.rho,
                  method=args.method, constant=not args.no_constant, keep_dc=args.keep_dc)


def model_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword options of :func:`pmsm_sysid.identify` that the command line asks for."""
    return {"output": args.output, "input": args.input, "ny": args.ny, "nu": args.nu,
            "degree": args.degree, "terms": args.terms, "delay": args.delay,
            "estimate": args.estimate, "validate": None if args.no_validate else args.validate,
            "criterion": args.criterion, "rho": args.rho, "method": args.method,
            "constant": not args.no_constant, "keep_dc": args.keep_dc,
            "corr_lags": args.corr_lags, "form": args.form}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", metavar="BAG", help="rosbag2 recording (directory)")
    p.add_argument("--namespace", type=ros_name, default=None,
                   help="input namespace (e.g. /pmsm) or JointState topic, for a bag that "
                        "holds several (default: found by itself)")
    p.add_argument("--joint", metavar="NAME", default=None,
                   help="JointState recordings of several joints (ros2_control): the axis's "
                        "joint")
    add_model_options(p)
    p.add_argument("--json", metavar="FILE", help="write the result as JSON ('-' = stdout)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar on the terminal (there is none when not a terminal)")


def _table(d: dict[str, Any]) -> str:
    lines = [f"{'Model term':<18} {'Estimate':>13} {'Std. dev.':>12} {'ERR':>10}"]
    for t in d["terms"]:
        lines.append(f"{t['name']:<18} {t['estimate']:>13.5e} {t['std']:>12.4e} {t['err']:>10.6f}")
    return "\n".join(lines)


def _fmt(x: Any) -> str:
    return "n/a" if x is None else f"{x:.4g}"


def correlation_lines(tests: dict[str, Any]) -> list[str]:
    """The five correlation tests, each with what its pass or FAIL rests on."""
    band = next(iter(tests.values()))["band"]
    out = [f"correlation tests of the residuals (95 % band +-{band:.3f}; pass: no more lags "
           "outside the band than white residuals give 199 times in 200, none beyond the "
           "limit):"]
    for k, t in tests.items():
        line = f"  {k:<5} {'pass' if t['pass'] else 'FAIL':<5}"
        if "n_allowed" in t:
            line += (f" {t['n_outside']} of {t['n_lags']} lags outside ({t['n_allowed']} "
                     f"allowed), largest {t['max_abs']:.3f} (limit {t['max_allowed']:.3f})")
        else:
            line += f" largest {t['max_abs']:.3f}"
        out.append(line)
    return out


def _summary(d: dict[str, Any]) -> str:
    v = d["validation"]
    est, val = v["estimation"], v["validation"]
    out = [f"estimation {d['estimate'][0]}:{d['estimate'][1]}: model predicted output "
           f"NMSE {_fmt(est['nmse'])}, R2 {_fmt(est['r2'])}; one-step-ahead R2 "
           f"{_fmt(est['osa_r2'])}"]
    if val is not None:
        out.append(f"validation {d['validate'][0]}:{d['validate'][1]}: model predicted output "
                   f"NMSE {_fmt(val['nmse'])}, R2 {_fmt(val['r2'])}; one-step-ahead R2 "
                   f"{_fmt(val['osa_r2'])}")
    if v["free_run_diverged"]:
        out.append("warning: the model predicted output diverged (unstable model)")
    out.extend(correlation_lines(v["correlation_tests"]))
    for w in (d.get("data_check") or {}).get("warnings", []):
        out.append(f"warning: {w}")
    return "\n".join(out)


def _alignment_note(report: Any, out: Any) -> None:
    """Say what reading the bag dropped or noticed (nothing is printed for a clean bag)."""
    r = report
    if r.n_unaligned or r.n_duplicates or r.n_out_of_order or r.n_nonfinite or r.n_gaps:
        print(f"warning: reading the bag: {r.summary()}", file=out)
    if r.n_out_of_order:
        print(f"warning: {r.n_out_of_order} messages are stamped earlier than messages "
              "received before them (reordered, or a clock jump): they were sorted by stamp, "
              "a repeated stamp keeps the first received", file=out)


def run(args: argparse.Namespace) -> int:
    from ..api import identify
    from ..progress import activity

    with activity("identify"):
        fit = identify(args.bag, namespace=args.namespace, joint=args.joint,
                       **model_options(args))
    d = fit.to_dict()
    out = sys.stderr if args.json == "-" else sys.stdout
    _alignment_note(fit.alignment, out)
    st = d["structure"]
    print(f"{d['input']} -> {d['output']}: {args.method}, {len(d['terms'])} terms of "
          f"{st['n_candidates']} candidates (ny={st['ny']}, nu={st['nu']}, degree="
          f"{st['degree']}, d={st['delay']}), {d['sample_rate_hz']:g} Hz, "
          f"{d['timing_ms']['total']:.0f} ms", file=out)
    print(_table(d), file=out)
    print(f"sum of ERR {d['sum_err']:.6f}", file=out)
    print(_summary(d), file=out)
    write_json(d, args.json)
    return 0
