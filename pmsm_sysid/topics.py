"""Topic names and layouts shared by nodes, recorder, replay and monitor.

Every topic a pipeline creates lives under its namespace (default ``/pmsm``), and its nodes
are named under it (``/pmsm/pmsm_identifier``): the nodes are created in the namespace and
use the *relative* names below, so one pipeline per motor can share a network, and ROS remap
rules (``-r model:=...``, ``-r __ns:=/axis2``) apply as usual. Only ``/diagnostics`` (the
standard health topic) and the sim clock's ``/clock`` are absolute.

No ROS imports here: message type names are strings as rosbag2 writes them.
"""

from __future__ import annotations

DEFAULT_NAMESPACE = "/pmsm"

# --- inputs (relative names) ------------------------------------------------------------
THRUST = "thrust"
SPEED = "speed"
POSITION = "position"

THRUST_TYPE = "geometry_msgs/msg/WrenchStamped"
SPEED_TYPE = "geometry_msgs/msg/TwistStamped"
POSITION_TYPE = "geometry_msgs/msg/PointStamped"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"

INPUT_TYPES = {THRUST: THRUST_TYPE, SPEED: SPEED_TYPE, POSITION: POSITION_TYPE}

# --- identification outputs (relative names) -----------------------------------------------
# Standard common_interfaces types on the wire; the package's own schemas in msg_schemas/
# document the JSON layouts and are registered with rosbags.
MODEL = "model"                          # std_msgs/msg/String, identify JSON
RIDGES = "ridges"                        # std_msgs/msg/String, gfrf JSON
RIDGE_FREQUENCIES = "ridge_frequencies"  # std_msgs/msg/Float64MultiArray
VALIDATION = "validation"                # diagnostic_msgs/msg/DiagnosticArray
CHANGE = "change"                        # diagnostic_msgs/msg/DiagnosticArray

STRING_TYPE = "std_msgs/msg/String"
DIAGNOSTIC_ARRAY_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
OUTPUT_TYPES = {
    MODEL: STRING_TYPE, RIDGES: STRING_TYPE,
    RIDGE_FREQUENCIES: "std_msgs/msg/Float64MultiArray",
    VALIDATION: DIAGNOSTIC_ARRAY_TYPE, CHANGE: DIAGNOSTIC_ARRAY_TYPE,
}

#: The standard health topic (absolute: the diagnostic aggregator listens there).
DIAGNOSTICS = "/diagnostics"

# --- plottable numbers: ``stats/<output>/<quantity>`` (relative) -----------------------------
STATS = "stats"
FLOAT64_TYPE = "std_msgs/msg/Float64"
INT32_TYPE = "std_msgs/msg/Int32"
FLOAT64_ARRAY_TYPE = "std_msgs/msg/Float64MultiArray"
#: quantity -> (type, unit, what it is), published per identified output.
STAT_TOPICS: dict[str, tuple[str, str, str]] = {
    "free_run_r2": (FLOAT64_TYPE, "1", "R2 of the free-run prediction of an earlier model on "
                    "the next independent window (cross-validation)"),
    "free_run_nrmse": (FLOAT64_TYPE, "1", "NRMSE of that free run (RMSE / std of the output)"),
    "terms": (INT32_TYPE, "count", "terms of the newest model (the constant included)"),
    "change_statistic": (FLOAT64_TYPE, "1", "combined change score S of the newest window "
                         "(a change is reported when S >= change.s_confirm twice running)"),
    "h1_peak_hz": (FLOAT64_TYPE, "Hz", "frequency of the strongest H1 peak of the newest "
                   "analysed model"),
    "h1_peak_gain_db": (FLOAT64_TYPE, "dB", "gain of that H1 peak"),
    "ridge_frequencies_hz": (FLOAT64_ARRAY_TYPE, "Hz", "frequencies of the H1 peaks and the "
                             "H2/H3 ridges of the newest analysed model, in the order of "
                             "ridge_frequencies' rows"),
}


def normalize_namespace(namespace: str) -> str:
    """``"a"``, ``"/a/"`` -> ``"/a"``; ``""`` or ``"/"`` -> ``"/"`` (the root)."""
    ns = namespace.strip().strip("/")
    return "/" + ns if ns else "/"


def topic_name(namespace: str, name: str) -> str:
    """Full name of the relative topic ``name`` under ``namespace`` (``/pmsm/model``)."""
    ns = normalize_namespace(namespace)
    return f"{ns.rstrip('/')}/{name}"


def input_topic(namespace: str, signal: str) -> str:
    """Full topic name of one input signal under ``namespace`` (``/pmsm/thrust``)."""
    return topic_name(namespace, signal)


def stat_topic(output: str, quantity: str) -> str:
    """Relative name of one plottable number of ``output`` (``stats/speed/free_run_r2``)."""
    return f"{STATS}/{output}/{quantity}"


def output_topics(namespace: str) -> dict[str, str]:
    """Full name -> type of the identification outputs under ``namespace`` (no stats)."""
    return {topic_name(namespace, name): t for name, t in OUTPUT_TYPES.items()}


def diagnostic_name(namespace: str, node: str) -> str:
    """Status name of one node's health on /diagnostics (``pmsm_sysid: /pmsm identifier``)."""
    return f"pmsm_sysid: {normalize_namespace(namespace)} {node}"
