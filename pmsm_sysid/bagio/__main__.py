"""``python -m pmsm_sysid.bagio repair BAG``: make a bag whose recording was killed readable."""

from __future__ import annotations

import argparse
import sys

from ..core.errors import PmsmSysidError
from .recorder import repair


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pmsm_sysid.bagio",
                                     description=__doc__.split(":")[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    rep = sub.add_parser("repair",
                         help="sqlite3: rebuild metadata.yaml; mcap: rewrite from complete chunks")
    rep.add_argument("bag")
    args = parser.parse_args(argv)
    try:
        n = repair(args.bag)
    except PmsmSysidError as exc:
        print(f"repair: error: {exc}", file=sys.stderr)
        return 2
    if n == 0:  # readable now, but empty: nothing of the recording came back
        print(f"repair: error: {args.bag}: no message could be salvaged (none of it was "
              "written completely)", file=sys.stderr)
        return 2
    print(f"{args.bag}: repaired, {n} messages")
    return 0


if __name__ == "__main__":
    sys.exit(main())
