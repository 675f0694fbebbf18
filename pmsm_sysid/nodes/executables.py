"""One node per process: the executables ``sim``, ``identifier``, ``gfrf`` and ``diagnose``.

After ``colcon build`` they are in ``install/pmsm_sysid/lib/pmsm_sysid/``, where ``ros2 run``
and launch files look, so a user's own launch file composes the pipeline node by node::

    ros2 run pmsm_sysid sim
    ros2 run pmsm_sysid identifier --ros-args -r __ns:=/axis2 --params-file tune.yaml
    ros2 run pmsm_sysid gfrf --ros-args -r __ns:=/axis2
    ros2 run pmsm_sysid diagnose --ros-args -p plant_file:=my_drive.yaml   # or sim_namespace:=/twin

Each starts its node (``/pmsm/pmsm_sim``, ``/pmsm/pmsm_identifier``, ``/pmsm/pmsm_gfrf``:
the pipeline's namespace, ``-r __ns:=/x`` moves it) on a private rclpy context with the
ROS arguments after ``--ros-args`` (namespace, node name, parameters, params files, remaps;
a params-file section keyed by the bare node name applies to that node in its namespace, as
for ``pmsm-sysid run``), spins it in a ``SingleThreadedExecutor`` until SIGINT or SIGTERM,
then destroys it (its worker process ends with it) and exits 0. Bad parameters or
arguments: one line on stderr, exit 2.

Defaults are those of ``pmsm-sysid run``: the sim is the packaged ``drive`` plant under
``broadband`` excitation on the wall clock (any plant-file key, ``excitation``,
``amplitude_n``, ``seed`` ... as a parameter); the identifier, GFRF and diagnosis nodes have
their own parameter defaults (``ros2 param describe`` lists them); the diagnosis node needs
its reference, ``plant_file`` or ``sim_namespace``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

from ..topics import DEFAULT_NAMESPACE

NODE_HELP = {
    "sim": "the simulated linear PMSM: publishes <ns>/thrust, <ns>/speed, <ns>/position at "
           "500 Hz (default plant: drive, excitation: broadband)",
    "identifier": "online NARX identification of <ns>/thrust, speed, position (or a "
                  "JointState topic): models on <ns>/model, validation, change events",
    "gfrf": "GFRFs and ridges of each model on <ns>/model: <ns>/ridges, "
            "<ns>/ridge_frequencies",
    "diagnose": "live sim-to-real diagnosis of <ns>/thrust, speed, position against a plant "
                "file (-p plant_file:=PLANT.yaml) or a simulator's topics (-p "
                "sim_namespace:=/twin): <ns>/diagnosis, <ns>/stats/diagnosis/...",
}
EPILOG = """\
ROS arguments after --ros-args, as for any ROS 2 executable, e.g.
  --ros-args -r __ns:=/axis2 --params-file params.yaml -p hop:=100 -r thrust:=/drive/force
SIGINT or SIGTERM stops the node cleanly (exit 0).
"""


def _make(kind: str, context: Any) -> Any:
    """The node ``kind`` on ``context`` (parameters from the context's ROS arguments)."""
    if kind == "sim":
        from ..core.physics.plant import load_plant
        from .sim_node import MotorSimNode

        return MotorSimNode(context=context, plant=load_plant("drive"),
                            excitation="broadband", namespace=DEFAULT_NAMESPACE)
    if kind == "identifier":
        from .identifier_node import IdentifierNode

        return IdentifierNode(context=context, namespace=DEFAULT_NAMESPACE)
    if kind == "diagnose":
        from .diagnosis_node import DiagnosisNode

        return DiagnosisNode(context=context, namespace=DEFAULT_NAMESPACE)
    from .gfrf_node import GfrfNode

    return GfrfNode(context=context, namespace=DEFAULT_NAMESPACE)


def run_node(kind: str, argv: Sequence[str] | None = None) -> int:
    """Start node ``kind`` alone and spin it until SIGINT/SIGTERM (see the module doc)."""
    from ..cli import NO_ROS, ros_missing
    from ..cli import _Parser as OneLineParser  # usage errors: one line, exit 2
    from ..core.errors import PmsmSysidError
    from ..rosargs import split_ros_args

    own, ros_args = split_ros_args(sys.argv[1:] if argv is None else argv)
    parser = OneLineParser(prog=kind, description=NODE_HELP[kind], epilog=EPILOG,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    if own:
        parser.parse_args(own)  # --help, or a one-line usage error (exit 2)
    if ros_missing() is not None:
        print(f"{kind}: error: this node {NO_ROS}", file=sys.stderr)
        return 2
    try:
        _spin(kind, ros_args)
    except PmsmSysidError as exc:
        print(f"{kind}: error: {' '.join(str(exc).splitlines())}", file=sys.stderr)
        return 2
    return 0


def _spin(kind: str, ros_args: list[str]) -> None:
    from ..rosargs import prepared
    from ..rosutil import ros_session, stop_on_signals

    with prepared(ros_args, DEFAULT_NAMESPACE) as args, ros_session(ros_args=args) as session, \
            stop_on_signals(session.stop):
        node = session.add(_make(kind, session.context))
        node.get_logger().info(f"{kind} node {node.get_fully_qualified_name()} running")
        session.spin_for(None)
        if kind in ("identifier", "diagnose"):
            node.publish_results()  # what the worker finished before the stop


def _entry(kind: str) -> Callable[[], int]:
    def main() -> int:
        return run_node(kind)

    main.__doc__ = f"``{kind}``: {NODE_HELP[kind]}"
    return main


sim = _entry("sim")
identifier = _entry("identifier")
gfrf = _entry("gfrf")
diagnose = _entry("diagnose")

__all__ = ["diagnose", "gfrf", "identifier", "run_node", "sim"]
