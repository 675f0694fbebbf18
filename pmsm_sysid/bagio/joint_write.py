"""Writing a recording in the ros2_control layout: one ``sensor_msgs/JointState`` topic.

A simulator driven through ros2_control (Gazebo, Isaac Sim) publishes its joints on
``/joint_states`` (joint_state_broadcaster): ``effort`` = thrust, ``velocity`` = speed,
``position`` = position for each named joint, all under one stamp. :func:`write_joint_states`
writes a :class:`Recording` that way, so the sample bags hold both layouts
:func:`.read.read_recording` reads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Writer

from .. import topics as tp
from ..core.errors import BagError, PmsmSysidError
from ..core.recording.signals import Recording
from .common import DEFAULT_QOS, connection_args, storage_plugin, typestore
from .write import _custom_data, _stamps_ns

DEFAULT_TOPIC = "/joint_states"


def write_joint_states(path: str | Path, rec: Recording, *, topic: str = DEFAULT_TOPIC,
                       joint: str = "axis", storage: str = "mcap") -> None:
    """Write ``rec`` as JointState messages of one joint on ``topic`` (stamps ``rec.t``;
    no velocities when the recording's speed is derived). Refuses to overwrite a path."""
    path = Path(path)
    if path.exists():
        raise BagError(f"{path} exists already, not overwriting")
    plugin = storage_plugin(storage)
    ns = _stamps_ns(rec.t)
    store = typestore()
    msg_t, header_t = store.types[tp.JOINT_STATE_TYPE], store.types["std_msgs/msg/Header"]
    time_t = store.types["builtin_interfaces/msg/Time"]
    msgdef, digest = connection_args(tp.JOINT_STATE_TYPE)
    empty = np.zeros(0, dtype=np.float64)
    try:
        with Writer(path, version=9, storage_plugin=plugin) as writer:
            conn = writer.add_connection(topic, tp.JOINT_STATE_TYPE, msgdef=msgdef,
                                         rihs01=digest, offered_qos_profiles=[DEFAULT_QOS])
            for key, value in _custom_data(rec, {"layout": f"JointState {topic} {joint}"}
                                           ).items():
                writer.set_custom_data(key, value)
            for k, stamp in enumerate(ns.tolist()):
                sec, nanosec = divmod(int(stamp), 1_000_000_000)
                msg = msg_t(header=header_t(stamp=time_t(sec=sec, nanosec=nanosec),
                                            frame_id=""),
                            name=[joint], position=np.array([rec.position[k]]),
                            velocity=empty if rec.speed_derived else np.array([rec.speed[k]]),
                            effort=np.array([rec.thrust[k]]))
                writer.write(conn, stamp, store.serialize_cdr(msg, tp.JOINT_STATE_TYPE))
    except PmsmSysidError:
        raise
    except Exception as exc:
        raise BagError(f"{path}: cannot write bag ({type(exc).__name__}: {exc})") from exc


__all__ = ["write_joint_states"]
