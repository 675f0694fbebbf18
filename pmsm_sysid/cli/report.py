"""``pmsm-sysid report (BAG | RESULT.json) --out DIR``: figures and tables as one HTML page.

A recording is identified first with the same options as ``identify`` (defaults: the
paper's speed case), then its GFRFs are computed; the page has the figures of Liu et al.
(2005) (I/O series, PSDs, model predicted output, correlation tests, H1, H2, H3) and its
tables of model terms. An identify JSON is reported with the recording its ``source`` names;
a gfrf or diagnose JSON with what it holds. Writes ``DIR/index.html``, one self-contained
file with every figure embedded (it opens offline and can be mailed on its own), and the
same figures as PNG files beside it; prints the page's path.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from .common import write_json
from .identify import add_model_options, fit_config

HELP = "figures and tables of a recording or a result JSON as one self-contained HTML page"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file", "out": "report"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="BAG|RESULT.json",
                   help="recording (rosbag2 directory) or a JSON from identify/gfrf/diagnose")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    add_model_options(p.add_argument_group("identification of a recording (as in 'identify')"))
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar on the terminal (there is none when not a terminal)")
    p.add_argument("--json", metavar="FILE",
                   help="write what was written (page, figures, notes) as JSON ('-' = stdout)")


def moved(result: Any, tmp: Path, final: Path) -> Any:
    """The report result with its paths moved from where it was built to where it is."""
    def move(p: Path) -> Path:
        try:
            return final / Path(p).relative_to(tmp)
        except ValueError:
            return Path(p)

    changes = {f.name: (tuple(move(x) for x in v) if isinstance(v, tuple) else move(v))
               for f in dataclasses.fields(result)
               if isinstance(v := getattr(result, f.name), Path)
               or (isinstance(v, tuple) and v and all(isinstance(x, Path) for x in v))}
    return dataclasses.replace(result, **changes)


def run(args: argparse.Namespace) -> int:
    from ..report import ReportOptions, build_report
    from ..validate import atomic_dir

    options = ReportOptions(input=args.input, output=args.output, config=fit_config(args),
                            estimate=args.estimate,
                            validate=None if args.no_validate else args.validate,
                            corr_lags=args.corr_lags, form=args.form)
    with atomic_dir(args.out, "--out") as tmp:  # a complete report, or none at all
        result = build_report(args.source, tmp, options)
    result = moved(result, tmp, Path(args.out))
    out = sys.stderr if args.json == "-" else sys.stdout
    for note in result.notes:
        print(f"note: {note}", file=out)
    print(f"{len(result.figures)} figures; report: {result.index.resolve()}", file=out)
    write_json(result.to_dict(), args.json)
    return 0
