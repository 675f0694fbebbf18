"""Recordings on disk: :func:`read_bag` and :func:`write_bag` (rosbag2, no ROS installation
needed: the bags are read and written with the ``rosbags`` library)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.errors import OptionError
from ..core.recording.signals import Recording

if TYPE_CHECKING:
    from ..bagio import LoadedRecording
    from ..core.recording.spans import Excerpt

PathLike = str | os.PathLike[str]
STORAGES = ("mcap", "sqlite3")


def load_bag(path: PathLike, namespace: str | None = None,
             until_sample: int | None = None, joint: str | None = None) -> LoadedRecording:
    """The recording of a bag together with how its streams were aligned (for the CLI);
    ``until_sample``: only the samples before it are needed (reading may stop after them)."""
    from ..bagio import read_recording
    from ..validate import check_namespace

    if namespace is not None:
        check_namespace(namespace, "namespace")
    if joint is not None and not (isinstance(joint, str) and joint):
        raise OptionError(f"joint must be a joint name, got {joint!r}")
    return read_recording(Path(path), namespace=namespace, until_sample=until_sample,
                          joint_name=joint)


def load_excerpt(path: PathLike, namespace: str | None = None, *, max_samples: int,
                 split: float | None = None, joint: str | None = None,
                 use: str | None = None) -> Excerpt:
    """The spans of a bag that a fit within ``max_samples`` uses (all of it when it fits),
    read without reading the rest (:func:`pmsm_sysid.bagio.spans.read_excerpt`); ``use``:
    what they are for (a non-finite sample in them is then refused)."""
    from ..bagio.spans import read_excerpt
    from ..validate import check_namespace

    if namespace is not None:
        check_namespace(namespace, "namespace")
    if joint is not None and not (isinstance(joint, str) and joint):
        raise OptionError(f"joint must be a joint name, got {joint!r}")
    return read_excerpt(Path(path), namespace=namespace, max_samples=max_samples, split=split,
                        joint_name=joint, use=use)


def read_bag(path: PathLike, namespace: str | None = None, *,
             joint: str | None = None) -> Recording:
    """Read the thrust, speed and position of one motor axis from a rosbag2 recording.

    The bag holds ``<namespace>/thrust`` (``geometry_msgs/WrenchStamped``),
    ``<namespace>/speed`` (``TwistStamped``, optional: derived from position when absent) and
    ``<namespace>/position`` (``PointStamped``), or one ``sensor_msgs/JointState`` topic.
    Samples are aligned on ``header.stamp``. ``namespace=None`` finds the topics by
    themselves; name it when a bag holds several axes. A ``JointState`` topic (as
    ros2_control's joint_state_broadcaster records it) carrying several joints needs
    ``joint``, the name of the axis's joint: its ``effort`` is the thrust, ``velocity`` the
    speed and ``position`` the position.

    Returns a :class:`Recording` with equal-length numpy arrays ``t`` (s), ``thrust`` (N),
    ``speed`` (m/s), ``position`` (m) and the float ``sample_rate_hz``.

    Raises a :class:`PmsmSysidError` (one line saying why) when the bag is missing, damaged,
    or lacks the topics.

    Example:
        >>> import pmsm_sysid as ps
        >>> rec = ps.read_bag("bags/paper_speed_nominal")
        >>> len(rec), rec.sample_rate_hz
        (4500, 500.0)
        >>> rec.speed.dtype
        dtype('float64')
    """
    return load_bag(path, namespace, joint=joint).recording


def write_bag(recording: Recording, path: PathLike, *, namespace: str = "/pmsm",
              storage: str = "mcap", overwrite: bool = False) -> Path:
    """Write a :class:`Recording` as a stock rosbag2 directory and return its path.

    Three topics ``<namespace>/thrust``, ``/speed`` and ``/position``, stamped with
    ``recording.t``; message definitions are embedded, so ``ros2 bag`` and other rosbag2
    readers open it. ``storage`` is ``"mcap"`` or ``"sqlite3"``. An existing bag at ``path``
    is replaced only with ``overwrite=True`` (and only if it is a rosbag2 directory).

    Example:
        >>> import pmsm_sysid as ps, tempfile, os
        >>> rec = ps.simulate(duration=1.0)
        >>> out = ps.write_bag(rec, os.path.join(tempfile.mkdtemp(), "one_second"))
        >>> len(ps.read_bag(out))
        500
    """
    from ..bagio import write_recording
    from ..core.errors import BagError
    from ..validate import atomic_dir, check_namespace, check_output_dir, is_bag_dir

    if not isinstance(recording, Recording):
        raise OptionError(f"write_bag needs a Recording, got {type(recording).__name__}")
    if storage not in STORAGES:
        raise OptionError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
    check_namespace(namespace, "namespace")
    out = Path(path)
    if out.exists() and not overwrite:
        raise BagError(f"{out} exists already; pass overwrite=True to replace it")
    # the checks every output gets (missing directory, not a bag, cannot be written), then
    # built beside it and renamed: the bag is complete, or not there at all
    check_output_dir(out, "path", force=True, is_ours=is_bag_dir, what="rosbag2 directory")
    with atomic_dir(out, "path") as tmp:
        write_recording(tmp, recording, namespace=namespace, storage=storage)
    return out
