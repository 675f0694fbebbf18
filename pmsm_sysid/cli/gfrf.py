"""``pmsm-sysid gfrf MODEL``: GFRFs, H1 peaks, H2/H3 ridges and poles of an identified model.

MODEL is the JSON written by ``identify`` (or a ``run --json`` summary, whose ``last_model``
is used). Frequencies are normalised, in cycles/sample (Hz = f x sample rate). ``--at``
evaluates the symmetric H_n at one point (n = number of frequencies, 1..4) and is repeatable;
``--grid N`` adds H1 on N points and |H2|, |H3(f1, f2, f1)| on N x N grids (dB) to the JSON.
When the model JSON carries the ``excitation`` summary of its estimation input, every peak and
ridge is marked ``supported`` or not, with a note (see docs/frequency.md).
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any, TextIO

from .common import write_json

HELP = "GFRFs, H1 peaks, H2/H3 ridges and poles of an identified model (identify JSON)"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file"}
MAX_ORDER = 4


def _point(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(x) for x in text.replace(" ", "").split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"expected 'f1[,f2[,f3[,f4]]]' in cycles/sample, got '{text}'") from exc
    if not 1 <= len(values) <= MAX_ORDER:
        raise argparse.ArgumentTypeError(f"1 to {MAX_ORDER} frequencies per point, got '{text}'")
    for v in values:
        if not math.isfinite(v) or abs(v) > 0.5:
            raise argparse.ArgumentTypeError(
                f"normalised frequencies must be finite and within [-0.5, 0.5] (cycles/sample), "
                f"got '{text}'")
    return values


def _grid(text: str) -> int:
    from ..core.frequency.analysis import MAX_REPORT_GRID

    try:
        n = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected an integer, got '{text}'") from exc
    if not 2 <= n <= MAX_REPORT_GRID:
        raise argparse.ArgumentTypeError(
            f"grid must be 2..{MAX_REPORT_GRID} points per axis (got {n}): larger grids make "
            "JSON files of tens of MB; use the Python API for those")
    return n


def _orders(text: str) -> tuple[int, ...]:
    try:
        out = tuple(sorted({int(x) for x in text.split(",")}))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected e.g. '1,2,3', got '{text}'") from exc
    if not out or any(o not in (1, 2, 3) for o in out):
        raise argparse.ArgumentTypeError(f"orders are among 1, 2, 3, got '{text}'")
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL", help="model JSON from 'identify' ('-' = stdin)")
    p.add_argument("--at", type=_point, action="append", default=[], metavar="F1[,F2[,F3]]",
                   help="evaluate H_n^sym at these normalised frequencies (repeatable)")
    p.add_argument("--grid", type=_grid, metavar="N",
                   help="add H1, |H2| and the H3 slice f1 = f3 on N-point grids to the JSON")
    p.add_argument("--orders", type=_orders, default=(1, 2, 3), metavar="1,2,3",
                   help="which GFRFs to search for peaks/ridges (default 1,2,3)")
    p.add_argument("--json", metavar="FILE", help="write the gfrf JSON ('-' = stdout)")


def _stdin_json() -> Any:
    from ..validate import read_json_object

    return read_json_object("-", "a model JSON written by identify", stdin_text=sys.stdin.read())


def _num(x: float | None, width: int, fmt: str = ".2f") -> str:
    """A JSON number for printing; null (non-finite: at a pole on the unit circle) -> n/a."""
    return f"{'n/a':>{width}}" if x is None else f"{x:{width}{fmt}}"


def plural(n: int, noun: str) -> str:
    """``1 pole``, ``28 poles``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def complex_text(re: float | None, im: float | None) -> str:
    """``4.25635e-08 + 1.1799e-07j``, with the sign of the imaginary part."""
    if im is None or re is None:
        return f"{_num(re, 0, '.6g')} {_num(im, 0, '.6g')}j"
    return f"{re:.6g} {'-' if im < 0 else '+'} {abs(im):.6g}j"


def _print(res: dict[str, Any], out: TextIO) -> None:
    fs = res["sample_rate_hz"]
    radius = res["max_pole_radius"]
    print(f"linear part: {'stable' if res['stable'] else 'UNSTABLE'}, "
          f"{plural(len(res['poles']), 'pole')}, largest radius {radius:.4f} ({fs:g} Hz "
          "sampling)", file=out)
    for w in res["warnings"]:
        print(f"warning: {w}", file=out)
    for n in res.get("notes", []):
        print(f"note: {n}", file=out)
    print(f"identifiability: {res['identifiability']['rests_on']}", file=out)

    def mark(row: dict[str, Any]) -> str:
        return {True: "supported", False: "NOT supported", None: "unchecked"}[row["supported"]]

    print("H1 peaks:" if res["h1"]["peaks"] else "H1 peaks: none", file=out)
    for p in res["h1"]["peaks"]:
        print(f"  {p['kind']:<9} {p['freq_norm']:.4f} cyc/sample = {p['freq_hz']:7.2f} Hz  "
              f"{_num(p['gain_db'], 7)} dB  {_num(p['phase_deg'], 8)} deg  [{mark(p)}]",
              file=out)
    for order in ("h2", "h3"):
        block = res[order]
        ridges = [r for r in block["ridges"] if r["sign"] > 0]
        label = order.upper() + (" ridges (slice f1 = f3)" if order == "h3" else " ridges")
        if block.get("skipped"):
            print(f"{label}: not computed (--orders)", file=out)
            continue
        if block.get("zero"):
            print(f"{label}: none ({block['note']})", file=out)
            continue
        print(f"{label}:" if ridges else f"{label}: none", file=out)
        for r in ridges:
            print(f"  {r['kind']:<9} = +-{r['freq_norm']:.4f} cyc/sample = +-{r['freq_hz']:7.2f} Hz"
                  f"  level {_num(r['level_db'], 7)} dB  [{mark(r)}]", file=out)
        if block.get("note"):
            print(f"  note: {block['note']}", file=out)
    for e in res["eval"]:
        args = ", ".join(f"{f:g}" for f in e["f"])
        print(f"H{e['order']}({args}) = {complex_text(*e['h'])}  "
              f"({_num(e['gain_db'], 0, '.3f')} dB, "
              f"{_num(e['phase_deg'], 0)} deg)", file=out)


def run(args: argparse.Namespace) -> int:
    from ..api import gfrf

    model = _stdin_json() if args.model == "-" else args.model
    res = gfrf(model, at=args.at, grid=args.grid, orders=args.orders).to_dict()
    _print(res, sys.stderr if args.json == "-" else sys.stdout)
    write_json(res, args.json)
    return 0
