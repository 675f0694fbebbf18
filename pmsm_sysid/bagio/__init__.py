"""rosbag2 I/O: the only package that touches recordings on disk.

Bags are stock rosbag2 directories (``metadata.yaml`` + ``.mcap`` or ``.db3``) written with
``rosbags``: message definitions and type hashes are embedded and offered QoS profiles are
in the metadata, so ``ros2 bag info``, Foxglove and a plain ``rosbags`` ``AnyReader`` read
them without this package.

- :func:`write_recording` / :func:`read_recording`: whole recordings (the three input topics);
  :func:`write_joint_states`: the same as one ros2_control ``JointState`` topic;
- :func:`iter_raw`, :func:`bag_topics`: serialized messages in log order, for replay;
- :func:`list_axes`: the axes a bag holds (namespaces, JointState joints);
- :class:`BagRecorder`, :func:`repair`: streaming recording that survives being killed;
- :func:`typestore`: ROS 2 Jazzy types plus the package's ``msg_schemas`` as
  ``pmsm_sysid/msg/<Name>``.
"""

from __future__ import annotations

from .common import (
    DEFAULT_QOS,
    FRAME_ID,
    LoadedRecording,
    RawMessage,
    connection_args,
    open_reader,
    schema_dir,
    storage_plugin,
    typestore,
)
from .joint_write import write_joint_states
from .read import bag_topics, iter_raw, list_axes, read_recording
from .recorder import BagRecorder, repair, sigterm_as_exit
from .schemas import encode_model_msg, encode_ridges_msg, encode_validation_msg
from .write import write_recording

__all__ = [
    "DEFAULT_QOS", "FRAME_ID", "BagRecorder", "LoadedRecording", "RawMessage", "bag_topics",
    "connection_args", "encode_model_msg", "encode_ridges_msg", "encode_validation_msg",
    "iter_raw", "list_axes", "open_reader", "read_recording", "repair", "schema_dir",
    "sigterm_as_exit", "storage_plugin", "typestore", "write_joint_states",
    "write_recording",
]
