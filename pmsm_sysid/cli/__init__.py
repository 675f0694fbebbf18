"""``pmsm-sysid <verb>``: one entry point for every tool.

Each verb lives in its own module ``pmsm_sysid.cli.<verb>`` exposing ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Verb modules import only the standard
library at top level; heavy imports (numpy, rclpy, rosbags) happen inside ``run`` so that
``--help`` is instant. Any :class:`~pmsm_sysid.core.errors.PmsmSysidError` becomes one line on
stderr and exit code 2; usage errors also exit 2 with one line.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

VERBS = (
    "run", "simulate", "replay", "record", "monitor", "identify", "gfrf",
    "diagnose", "fit-plant", "fleet", "report", "import-mat",
)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line on stderr and exit 2."""

    def error(self, message: str) -> NoReturn:
        message = " ".join(message.splitlines())  # one line, whatever the user typed
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _module_name(verb: str) -> str:
    return "pmsm_sysid.cli." + verb.replace("-", "_")


ROS_ARGS_HELP = """\
ROS arguments: after the options above, --ros-args as for any ROS 2 executable, e.g.
  --ros-args --params-file params.yaml -p hop:=100 -r __ns:=/axis2
(a params-file section 'pmsm_identifier:' names that node in the pipeline's namespace;
'/**:' names every node; the options above win over --ros-args)
"""


def build_parser() -> argparse.ArgumentParser:
    from ..rosargs import ROS_VERBS

    parser = _Parser(prog="pmsm-sysid", description=__doc__.split("\n\n")[0].replace("``", ""))
    sub = parser.add_subparsers(dest="verb", metavar="VERB", parser_class=_Parser)
    sub.required = True
    for verb in VERBS:
        try:
            mod = importlib.import_module(_module_name(verb))
        except ModuleNotFoundError:
            continue  # verb not built yet in this checkout
        p = sub.add_parser(verb, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        if verb in ROS_VERBS:
            p.formatter_class = argparse.RawDescriptionHelpFormatter
            p.epilog = (p.epilog or "") + ROS_ARGS_HELP
        outputs = getattr(mod, "OUTPUTS", {})
        if outputs and "--force" not in p._option_string_actions:
            p.add_argument("--force", action="store_true",
                           help="replace existing output files (never a directory of other "
                                "things)")
        p.set_defaults(_run=mod.run, _outputs=outputs)
    return parser


#: Top-level modules that only a ROS 2 installation (or the ``[ros]`` extra) provides.
ROS_MODULES = frozenset({
    "rclpy", "rcl_interfaces", "builtin_interfaces", "std_msgs", "geometry_msgs",
    "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs", "ament_index_python",
})
NO_ROS = ("needs ROS 2 (rclpy) and it is not installed here: pip install 'pmsm_sysid[ros]' "
          "for the ROS 2 Jazzy wheels, or source a ROS 2 Jazzy installation")


def ros_missing() -> str | None:
    """None when rclpy imports; else why not (the module that is missing)."""
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        return str(exc)
    return None


#: BLAS thread pools are set to one thread unless the user chose otherwise: the work here is
#: many small products (a 71 x 71 x 1000 Gram per OFR step), for which a multi-threaded
#: OpenBLAS on a busy 2-core machine measured 25x slower (1.6 s instead of 65 ms per fit).
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def main(argv: Sequence[str] | None = None) -> int:
    for var in BLAS_THREAD_VARS:  # before any verb imports numpy
        os.environ.setdefault(var, "1")
    from ..core.errors import PmsmSysidError
    from ..rosargs import ROS_VERBS, check_ros_args, split_ros_args
    from .common import check_outputs

    parser = build_parser()
    own, ros_args = split_ros_args(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(own)
    if ros_args and args.verb not in ROS_VERBS:
        parser.exit(2, f"pmsm-sysid {args.verb}: error: --ros-args applies to the ROS verbs "
                       f"only ({', '.join(ROS_VERBS)})\n")
    args.ros_args = ros_args
    if args.verb in ROS_VERBS and ros_missing() is not None:
        print(f"pmsm-sysid {args.verb}: error: this verb {NO_ROS}", file=sys.stderr)
        return 2
    from ..progress import silence

    was_quiet = silence(True) if getattr(args, "quiet", False) else None
    try:
        check_ros_args(ros_args)  # before any work: a missing params file is bad input
        check_outputs(args, args._outputs)  # before any work: a long run must not end unwritten
        return int(args._run(args))
    except PmsmSysidError as exc:
        text = " ".join(str(exc).splitlines())  # one line, whatever the input held
        print(f"pmsm-sysid {args.verb}: error: {text}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] not in ROS_MODULES:
            raise
        print(f"pmsm-sysid {args.verb}: error: this verb {NO_ROS} (no module "
              f"'{exc.name}')", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"pmsm-sysid {args.verb}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    finally:
        if was_quiet is not None:  # the bars' setting of the caller (main called in-process)
            silence(was_quiet)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
