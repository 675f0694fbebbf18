"""Topic names and layouts shared by nodes, recorder, replay and monitor.

No ROS imports here: message type names are strings as rosbag2 writes them.
"""

from __future__ import annotations

DEFAULT_NAMESPACE = "/pmsm"

THRUST = "thrust"
SPEED = "speed"
POSITION = "position"

THRUST_TYPE = "geometry_msgs/msg/WrenchStamped"
SPEED_TYPE = "geometry_msgs/msg/TwistStamped"
POSITION_TYPE = "geometry_msgs/msg/PointStamped"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"

INPUT_TYPES = {THRUST: THRUST_TYPE, SPEED: SPEED_TYPE, POSITION: POSITION_TYPE}

# Outputs of the identification side (standard common_interfaces types on the wire; the
# package's own schemas in msg_schemas/ document the layouts and are registered with rosbags).
SYSID_NAMESPACE = "/pmsm_sysid"
MODEL_TOPIC = f"{SYSID_NAMESPACE}/model"            # std_msgs/msg/String, identify JSON
RIDGES_TOPIC = f"{SYSID_NAMESPACE}/ridges"          # std_msgs/msg/String, gfrf JSON
RIDGES_ARRAY_TOPIC = f"{SYSID_NAMESPACE}/ridge_frequencies"  # std_msgs/msg/Float64MultiArray
VALIDATION_TOPIC = f"{SYSID_NAMESPACE}/validation"  # diagnostic_msgs/msg/DiagnosticArray
CHANGE_TOPIC = f"{SYSID_NAMESPACE}/change"          # diagnostic_msgs/msg/DiagnosticArray


def input_topic(namespace: str, signal: str) -> str:
    """Full topic name of one input signal under ``namespace`` (``/pmsm/thrust``)."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    return f"{ns}/{signal}"
