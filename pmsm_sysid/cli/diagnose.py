"""``pmsm-sysid diagnose (--plant PLANT | --sim SIM_BAG) --real BAG``: what physics does the
simulation leave out?

Locates the mismatch between the plant and the recording (equation error of inverse
dynamics: over time, position, velocity, frequency), names the missing effects from a
library of interpretable physics (forward regression by ERR, prewhitened F-tests with a
Bonferroni correction, held-out confirmation), estimates their parameters with standard
errors, builds the corrected plant (in the JSON as ``corrected_plant``; written as a plant
file only with ``--corrected-plant FILE``) and shows the fit before/after on estimation and
held-out data. Held-out data: ``--validate BAG2``, else the last 30 % of the recording. ``--json``
writes the diagnose JSON; ``--report DIR`` writes figures and an index.html.

With ``--sim SIM_BAG`` (a recording of the user's own simulator) instead of a plant file,
the simulator's plant is fitted from its recording and the real recording's too; the two
are compared parameter by parameter against both fits' errors (what the real drive has
beyond the simulation, what the simulation has that the real drive lacks, each change in
words), and the simulation's plant with the changes applied is the corrected plant.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import budget, parse_fraction, ros_name, write_json, write_text

HELP = "sim-to-real: locate the mismatch, name the missing physics, model it, show the fit"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file", "corrected_plant": "file", "report": "report"}




def add_arguments(p: argparse.ArgumentParser) -> None:
    ref = p.add_mutually_exclusive_group(required=True)
    ref.add_argument("--plant", metavar="PLANT.yaml", help="the simulation's plant file")
    ref.add_argument("--sim", metavar="SIM_BAG",
                     help="a recording of the simulator instead of a plant file (rosbag2, "
                          "topics or JointState; its plant is fitted from it)")
    p.add_argument("--real", required=True, metavar="BAG", help="the real recording (rosbag2)")
    p.add_argument("--validate", metavar="BAG2",
                   help="held-out recording (default: the last 30%% of --real)")
    p.add_argument("--namespace", type=ros_name, default=None,
                   help="topic namespace or JointState topic of --real and --validate "
                        "(default: auto-detect)")
    p.add_argument("--sim-namespace", type=ros_name, default=None,
                   help="topic namespace or JointState topic of --sim (default: auto-detect)")
    p.add_argument("--joint", metavar="NAME", default=None,
                   help="JointState recordings of several joints (ros2_control): the axis's "
                        "joint in --real and --validate")
    p.add_argument("--sim-joint", metavar="NAME", default=None,
                   help="the same for --sim")
    p.add_argument("--alpha", type=parse_fraction, default=1e-3,
                   help="family-wise false-alarm level of each selection step (default 1e-3)")
    p.add_argument("--min-share", type=parse_fraction, default=0.01,
                   help="smallest share of the mismatch an effect must explain (default 0.01)")
    p.add_argument("--no-replay", action="store_true",
                   help="skip the short-horizon speed replay (output error)")
    p.add_argument("--max-samples", type=budget, default=None, metavar="N",
                   help="samples used at most of each recording (default 120000, at least "
                        "20000); a longer one is used in ten spans spread evenly over it, and "
                        "only those are read")
    p.add_argument("--no-gfrf", action="store_true",
                   help="skip the GFRF comparison of the real data's NARX with a noisy "
                        "simulated twin's")
    p.add_argument("--json", metavar="FILE", help="write the diagnose JSON ('-' = stdout)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar on the terminal (there is none when not a terminal)")
    p.add_argument("--corrected-plant", metavar="FILE",
                   help="write the corrected plant (the reference -- the plant file, or with "
                        "--sim the simulator's fitted plant -- with the effects found and the "
                        "changes applied) as a YAML plant file; without it the corrected plant "
                        "is in the JSON and the report only")
    p.add_argument("--report", metavar="DIR", help="write figures (PNG) and DIR/index.html")


def run(args: argparse.Namespace) -> int:
    from ..api import diagnose
    from ..progress import activity

    budget = {} if args.max_samples is None else {"max_samples": args.max_samples}
    with activity("diagnose"):
        found = diagnose(args.plant, args.real, validate=args.validate,
                         namespace=args.namespace, alpha=args.alpha, min_share=args.min_share,
                         replay=not args.no_replay, gfrf=not args.no_gfrf, sim=args.sim,
                         sim_namespace=args.sim_namespace, joint=args.joint,
                         sim_joint=args.sim_joint, **budget)
    real = found.real
    total = found.excerpt.total if found.excerpt is not None else len(real)
    used = "" if total == len(real) else f", {len(real)} used: see 'data used'"
    out = sys.stderr if args.json == "-" else sys.stdout
    what = f"plant {args.plant}" if args.sim is None else f"simulator's recording {args.sim}"
    print(f"diagnose: {what} vs recording {args.real} "
          f"({total} samples at {real.sample_rate_hz:g} Hz{used}"
          f"{', speed derived from position' if real.speed_derived else ''})", file=out)
    print(found.summary(), file=out)
    write_json(found.to_dict(), args.json)
    if args.corrected_plant:
        write_text(found.corrected.to_yaml(), args.corrected_plant, "--corrected-plant")
    if args.report:
        from ..report.diagnose import write_report
        from ..validate import atomic_dir

        with atomic_dir(args.report, "--report") as tmp:  # complete, or none at all
            index = write_report(found.result, tmp,
                                 title=f"{args.plant or args.sim} vs {args.real}")
        print(f"report: {Path(args.report) / Path(index).relative_to(tmp)}", file=out)
    return 0
