"""``pmsm-sysid report (BAG | RESULT.json) --out DIR``: figures and tables as one HTML page.

A recording is identified first with the same options as ``identify`` (defaults: the
paper's speed case), then its GFRFs are computed; the page has the seed's figures (I/O
series, PSDs, model predicted output, correlation tests, H1, H2, H3) and tables. An identify
JSON is reported with the recording its ``source`` names; a gfrf or diagnose JSON with what
it holds. Writes ``DIR/index.html`` and PNGs beside it; prints the page's path.
"""

from __future__ import annotations

import argparse
import sys

from .common import parse_fraction, parse_range, write_json
from .identify import _count

HELP = "figures and tables of a recording or a result JSON as an HTML page with PNGs"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="BAG|RESULT.json",
                   help="recording (rosbag2 directory) or a JSON from identify/gfrf/diagnose")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    g = p.add_argument_group("identification of a recording (as in 'identify')")
    g.add_argument("--input", default="thrust", choices=("thrust",), help="input signal")
    g.add_argument("--output", default="speed", choices=("speed", "position"),
                   help="output signal (default speed)")
    g.add_argument("--ny", type=_count, default=30, help="output lags (default 30)")
    g.add_argument("--nu", type=_count, default=40, help="input lags (default 40)")
    g.add_argument("--degree", type=int, choices=(1, 2, 3), default=2,
                   help="polynomial degree (default 2)")
    g.add_argument("--terms", type=_count, default=15, help="number of terms (default 15)")
    g.add_argument("--delay", type=_count, default=1, help="input delay d (default 1)")
    g.add_argument("--estimate", type=parse_range, default=(1000, 2000), metavar="START:STOP",
                   help="estimation samples, 0-based half-open (default 1000:2000)")
    g.add_argument("--validate", type=parse_range, default=(3000, 4000), metavar="START:STOP",
                   help="validation samples (default 3000:4000)")
    g.add_argument("--no-validate", action="store_true", help="no validation window")
    g.add_argument("--criterion", choices=("terms", "err", "aic", "bic"), default="terms",
                   help="model size rule (default terms)")
    g.add_argument("--rho", type=parse_fraction, default=1e-3,
                   help="ERR tolerance for --criterion err")
    g.add_argument("--method", choices=("iofr", "ofr"), default="iofr",
                   help="term selection (default iofr)")
    g.add_argument("--corr-lags", type=_count, default=20,
                   help="lags of the correlation tests (default 20)")
    p.add_argument("--json", metavar="FILE",
                   help="write what was written (page, figures, notes) as JSON ('-' = stdout)")


def run(args: argparse.Namespace) -> int:
    from ..core.errors import DataError
    from ..core.identify import FitConfig
    from ..core.model import Structure
    from ..report import ReportOptions, build_report

    if args.terms < 1:
        raise DataError("--terms must be at least 1")
    config = FitConfig(structure=Structure(ny=args.ny, nu=args.nu, degree=args.degree,
                                           delay=args.delay),
                       n_terms=args.terms, criterion=args.criterion, rho=args.rho,
                       method=args.method)
    options = ReportOptions(input=args.input, output=args.output, config=config,
                            estimate=args.estimate,
                            validate=None if args.no_validate else args.validate,
                            corr_lags=args.corr_lags)
    result = build_report(args.source, args.out, options)
    out = sys.stderr if args.json == "-" else sys.stdout
    for note in result.notes:
        print(f"note: {note}", file=out)
    print(f"{len(result.figures)} figures; report: {result.index.resolve()}", file=out)
    write_json(result.to_dict(), args.json)
    return 0
