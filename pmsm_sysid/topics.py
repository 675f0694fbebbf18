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
DIAGNOSIS = "diagnosis"                  # std_msgs/msg/String, diagnose JSON of each span

#: history depth of the model topic, publisher and subscribers (models may come in bursts:
#: each publish of the identifier sends every model fitted since the last one)
MODEL_DEPTH = 50

STRING_TYPE = "std_msgs/msg/String"
DIAGNOSTIC_ARRAY_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
OUTPUT_TYPES = {
    MODEL: STRING_TYPE, RIDGES: STRING_TYPE,
    RIDGE_FREQUENCIES: "std_msgs/msg/Float64MultiArray",
    VALIDATION: DIAGNOSTIC_ARRAY_TYPE, CHANGE: DIAGNOSTIC_ARRAY_TYPE, DIAGNOSIS: STRING_TYPE,
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


# --- plottable numbers of the live diagnosis: ``stats/diagnosis/<quantity>`` (relative) -----
DIAGNOSIS_STATS = "diagnosis"
#: effect -> (param, unit) published per diagnosis as ``stats/diagnosis/<effect>/<param>``
#: (NaN while the effect is not named; names and signs of the diagnose JSON); the first is
#: the effect's headline number.
DIAGNOSIS_PARAMS: dict[str, tuple[tuple[str, str], ...]] = {
    "coulomb_friction": (("amplitude_n", "N"),),
    "stribeck_friction": (("static_n", "N"), ("velocity_mps", "m/s")),
    "cogging": (("amplitude_n", "N"), ("pitch_m", "m"), ("phase_rad", "rad")),
    "thrust_ripple": (("relative", "1"), ("pitch_m", "m"), ("phase_rad", "rad")),
    "force_offset": (("amplitude_n", "N"),),
    "thrust_lag": (("tau_s", "s"),),
    "transport_delay": (("delay_s", "s"),),
    "spring": (("stiffness_n_per_m", "N/m"),),
    "mass_error": (("mass_kg", "kg"),),
    "viscous_error": (("viscous_n_per_mps", "N/(m/s)"),),
}
#: quantity -> (type, unit, what it is): the counts and fit of each diagnosis
DIAGNOSIS_COUNTS: dict[str, tuple[str, str, str]] = {
    "effects_named": (INT32_TYPE, "count", "library effects the latest diagnosis named"),
    "unexplained": (INT32_TYPE, "count", "mismatches no library effect explains (reported "
                    "as unexplained, with the axis they live on)"),
    "force_nrmse_before": (FLOAT64_TYPE, "1", "force NRMSE of the plant on the held-out last "
                           "30 % of the span (equation error of the inverse dynamics)"),
    "force_nrmse_after": (FLOAT64_TYPE, "1", "the same with what the diagnosis found added"),
}


def diagnosis_stat_topics() -> dict[str, str]:
    """Relative name -> type of every plottable number of the live diagnosis."""
    out = {f"{STATS}/{DIAGNOSIS_STATS}/{q}": t for q, (t, _, _) in DIAGNOSIS_COUNTS.items()}
    out.update({f"{STATS}/{DIAGNOSIS_STATS}/{e}/{p}": FLOAT64_TYPE
                for e, params in DIAGNOSIS_PARAMS.items() for p, _ in params})
    return out


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
