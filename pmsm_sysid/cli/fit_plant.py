"""``pmsm-sysid fit-plant BAG --out PLANT.yaml``: the physical plant of any recording.

Identifies the mass and viscous damping (always) and every library effect the recording
shows (friction, offset, cogging, ripple, lag, delay, spring), each with its standard error,
significance and confidence, and writes a plant file that ``simulate``, the sim node and
``diagnose --plant`` accept. Structure no library effect explains is reported, not written.
Held-out data: ``--validate BAG2``, else the last 30 % of the recording.
"""

from __future__ import annotations

import argparse
import sys

from .common import budget, parse_fraction, ros_name, write_json, write_text

HELP = "the physical plant (mass, viscous damping, effects, with errors) of a recording"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"out": "file", "json": "file"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", metavar="BAG", help="the recording (rosbag2: topics or JointState)")
    p.add_argument("--out", required=True, metavar="PLANT.yaml",
                   help="the plant file to write")
    p.add_argument("--validate", metavar="BAG2",
                   help="held-out recording (default: the last 30%% of BAG)")
    p.add_argument("--namespace", type=ros_name, default=None,
                   help="topic namespace or JointState topic (default: auto-detect)")
    p.add_argument("--joint", metavar="NAME", default=None,
                   help="JointState recordings of several joints (ros2_control): the axis's "
                        "joint")
    p.add_argument("--alpha", type=parse_fraction, default=1e-3,
                   help="family-wise false-alarm level of each selection step (default 1e-3)")
    p.add_argument("--min-share", type=parse_fraction, default=0.01,
                   help="smallest share of the force an effect must explain (default 0.01)")
    p.add_argument("--max-samples", type=budget, default=None, metavar="N",
                   help="samples used at most of each recording (default 120000, at least "
                        "20000); a longer one is used in ten spans spread evenly over it, and "
                        "only those are read")
    p.add_argument("--json", metavar="FILE",
                   help="write the plant, its standard errors, effects and fit as JSON "
                        "('-' = stdout)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar on the terminal (there is none when not a terminal)")


def header(rec: object, path: str, total: int | None = None) -> str:
    """The first line: what was read (``total``: the recording's length, when only part of
    it was used)."""
    n = len(rec)  # type: ignore[arg-type]
    fs = getattr(rec, "sample_rate_hz", 0.0)
    derived = ", speed derived from position" if getattr(rec, "speed_derived", False) else ""
    used = "" if total in (None, n) else f", {n} used: see 'data used'"
    size = f"{n if total is None else total} samples at {fs:g} Hz{used}"
    return f"fit-plant: recording {path} ({size}{derived})"


def run(args: argparse.Namespace) -> int:
    from ..api import fit_plant
    from ..progress import activity

    with activity("fit-plant"):
        size = {} if args.max_samples is None else {"max_samples": args.max_samples}
        fit = fit_plant(args.bag, validate=args.validate, namespace=args.namespace,
                        alpha=args.alpha, min_share=args.min_share, joint=args.joint,
                        **size)
    out = sys.stderr if args.json == "-" else sys.stdout
    total = fit.excerpt.total if fit.excerpt is not None else None
    print(header(fit.recording, args.bag, total), file=out)
    print(fit.summary(), file=out)
    head = (f"# Plant fitted by pmsm-sysid fit-plant from {args.bag}: mass, viscous damping\n"
            "# and the effects found (standard errors in its --json); rs_ohm, ls_h and "
            "flux_wb\n# are not identified from a force balance and keep the nominal "
            "values.\n")
    write_text(head + fit.plant.to_yaml(), args.out, "--out")
    write_json(fit.to_dict(), args.json)
    print(f"wrote {args.out}", file=out)
    return 0
