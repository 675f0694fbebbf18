"""``pmsm-sysid import-mat MAT --out BAG``: the EMPS ``.mat`` layout as a recording.

Keys: ``t`` (s), ``qm`` measured position (m), ``qg`` reference position (m), ``vir``
controller output (V), ``gtau`` (N/V), ``kp``, ``kv``. Written: ``<ns>/thrust`` =
``gtau * vir``, ``<ns>/position`` = ``qm``, ``<ns>/reference`` = ``qg`` (PointStamped), all
stamped with ``t``. The rig has no speed sensor, so no speed topic is written: readers derive
speed from position (causal backward difference) and mark it derived; the bag's ``custom_data``
says so (``pmsm_sysid.speed``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import ros_name

HELP = "convert the EMPS .mat layout into a recording (thrust = gtau*vir, position = qm)"
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file", "out": "bag"}

REQUIRED = ("t", "qm", "vir", "gtau")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mat", metavar="MAT", help="EMPS-layout .mat file (e.g. DATA_EMPS.mat)")
    p.add_argument("--out", required=True, metavar="BAG", help="rosbag2 directory to create")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap",
                   help="rosbag2 storage plugin (default: mcap)")
    p.add_argument("--namespace", type=ros_name, default="/pmsm",
                   help="topic namespace (default: /pmsm)")
    p.add_argument("--json", metavar="FILE", help="write a summary as JSON ('-' = stdout)")


def load_mat(path: str | Path) -> dict[str, Any]:
    """The EMPS arrays as float64: t, qm, vir (1-D, same length), gtau (scalar), qg if present."""
    import numpy as np
    import scipy.io

    from ..core.errors import DataError

    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path}: is a directory, not a .mat file")
    if not path.is_file():
        raise DataError(f"{path}: no such .mat file")
    try:
        raw = scipy.io.loadmat(str(path))
    except NotImplementedError as exc:
        raise DataError(f"{path}: MATLAB v7.3 (HDF5) files are not supported; "
                        "save with -v7") from exc
    except Exception as exc:
        raise DataError(f"{path}: not a readable MATLAB .mat file ({exc})") from exc
    missing = [k for k in REQUIRED if k not in raw]
    if missing:
        have = ", ".join(k for k in raw if not k.startswith("__")) or "none"
        raise DataError(f"{path}: missing key(s) {', '.join(missing)} (keys: {have})")
    out: dict[str, Any] = {}
    for key in ("t", "qm", "vir", "qg", "gtau", "kp", "kv"):
        if key in raw:
            if np.iscomplexobj(raw[key]):  # never take the real part silently
                raise DataError(f"{path}: '{key}' holds complex numbers; a recording is real")
            try:
                out[key] = np.asarray(raw[key], dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise DataError(f"{path}: key '{key}' is not numeric") from exc
    n = out["t"].size
    for key in ("t", "qm", "vir", "qg"):
        if key in out:
            if out[key].ndim > 2 or min(out[key].shape, default=0) > 1 or out[key].size != n:
                raise DataError(f"{path}: '{key}' must be a vector of {n} samples, "
                                f"got shape {out[key].shape}")
            out[key] = out[key].reshape(-1)
    for key in ("gtau", "kp", "kv"):
        if key in out:
            if out[key].size != 1:
                raise DataError(f"{path}: '{key}' must be a scalar, got shape {out[key].shape}")
            out[key] = float(out[key].reshape(-1)[0])
            if not np.isfinite(out[key]):
                raise DataError(f"{path}: '{key}' is not finite ({out[key]:g}); it must be a "
                                "finite gain" + (" (thrust = gtau * vir)" if key == "gtau"
                                                 else ""))
    for key in ("t", "qm", "vir", "qg"):
        if key in out and not np.all(np.isfinite(out[key])):
            raise DataError(f"{path}: '{key}' has non-finite samples")
    if not np.all(np.diff(out["t"]) > 0):
        raise DataError(f"{path}: 't' is not strictly increasing")
    with np.errstate(over="ignore", invalid="ignore"):
        if not np.all(np.isfinite(out["gtau"] * out["vir"])):
            raise DataError(f"{path}: thrust = gtau * vir overflows ('gtau' {out['gtau']:g}, "
                            f"'vir' up to {np.max(np.abs(out['vir'])):g})")
    return out


def run(args: argparse.Namespace) -> int:
    from ..bagio import read_recording, write_recording
    from ..core.recording.align import robust_period
    from ..core.recording.signals import Recording, derive_speed
    from ..validate import atomic_dir
    from .common import write_json

    mat = load_mat(args.mat)
    t, qm = mat["t"], mat["qm"]
    thrust = mat["gtau"] * mat["vir"]  # force = gtau * vir (N)
    meta: dict[str, str] = {k: repr(mat[k]) for k in ("gtau", "kp", "kv") if k in mat}
    meta["thrust"] = "gtau * vir"
    rec = Recording(t=t, thrust=thrust, speed=derive_speed(t, qm), position=qm,
                    sample_rate_hz=1.0 / robust_period(t), speed_derived=True,
                    source=str(Path(args.mat).resolve()), meta=meta)
    extra = {"reference": mat["qg"]} if "qg" in mat else None
    with atomic_dir(args.out, "--out") as tmp:  # complete and readable, or not there at all
        write_recording(tmp, rec, namespace=args.namespace, storage=args.storage,
                        extra_points=extra)
        loaded = read_recording(tmp, namespace=args.namespace)
    print(f"wrote {args.out}: {len(loaded.recording)} samples at "
          f"{loaded.recording.sample_rate_hz:.6g} Hz; thrust = gtau*vir, position = qm"
          f"{', reference = qg' if extra else ''}; no speed sensor: speed derived on reading")
    write_json({"out": str(args.out), "storage": args.storage, "source": rec.source,
                "samples": len(loaded.recording),
                "sample_rate_hz": loaded.recording.sample_rate_hz,
                "topics": loaded.topics, "speed_derived": loaded.report.speed_derived,
                "align": loaded.report.to_dict()}, args.json)
    return 0
