"""The package's own message schemas and the direct CDR coding of the input messages."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from pmsm_sysid.bagio import schema_dir, typestore
from pmsm_sysid.core.errors import BagError

STORAGES = ["mcap", "sqlite3"]
JAZZY = get_typestore(Stores.ROS2_JAZZY)


def _header(ns: int, frame: str = "x") -> object:
    time_t = JAZZY.types["builtin_interfaces/msg/Time"]
    return JAZZY.types["std_msgs/msg/Header"](
        stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)


# --------------------------------------------------------------------------- own schemas


def test_schemas_registered() -> None:
    names = sorted(p.stem for p in schema_dir().glob("*.msg"))
    assert names == ["CorrelationTest", "GfrfRidges", "NarxModel", "NarxTerm", "Ridge",
                     "ValidationStats"]
    store = typestore()
    for name in names:
        assert f"pmsm_sysid/msg/{name}" in store.types
    fields = [f[0] for f in store.fielddefs["pmsm_sysid/msg/NarxTerm"][1]]
    assert fields == ["name", "estimate", "std", "err"]


_SELF_DESCRIBING_CHECK = r"""
import json, sys
from pathlib import Path
from rosbags.highlevel import AnyReader
assert not any(m.startswith("pmsm_sysid") for m in sys.modules)
out = []
with AnyReader([Path(sys.argv[1])]) as r:
    for c, t, raw in r.messages():
        m = r.deserialize(raw, c.msgtype)
        out.append({"type": c.msgtype, "terms": [[x.name, x.estimate, x.std, x.err]
                                                 for x in m.terms],
                    "ny": m.ny, "fs": m.sample_rate_hz, "start": m.window_start.sec,
                    "frame": m.header.frame_id})
assert not any(m.startswith("pmsm_sysid") for m in sys.modules)
print(json.dumps(out))
"""


@pytest.mark.parametrize("storage", STORAGES)
def test_bag_with_own_messages_is_self_describing(tmp_path: Path, storage: str) -> None:
    from pmsm_sysid.bagio import BagRecorder

    store = typestore()
    t = store.types
    time_t = t["builtin_interfaces/msg/Time"]
    msg = t["pmsm_sysid/msg/NarxModel"](
        header=t["std_msgs/msg/Header"](stamp=time_t(sec=5, nanosec=0), frame_id="pmsm"),
        window_start=time_t(sec=2, nanosec=0), window_end=time_t(sec=4, nanosec=0),
        input_name="thrust", output_name="speed", sample_rate_hz=500.0, ny=30, nu=40,
        degree=2, delay=1, n_candidates=2556,
        terms=[t["pmsm_sysid/msg/NarxTerm"](name="y(k-1)", estimate=0.5, std=0.01, err=0.9),
               t["pmsm_sysid/msg/NarxTerm"](name="u(k-14)", estimate=33.7, std=0.99,
                                            err=0.043)],
        fit_time_s=0.25)
    bag = tmp_path / "models"
    with BagRecorder(bag, storage=storage) as rec:
        rec.add_topic("/pmsm_sysid/model_typed", "pmsm_sysid/msg/NarxModel")
        rec.write("/pmsm_sysid/model_typed", 5 * 10**9,
                  store.serialize_cdr(msg, "pmsm_sysid/msg/NarxModel"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([sys.executable, "-c", _SELF_DESCRIBING_CHECK, str(bag)], cwd=tmp_path,
                         capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    (got,) = json.loads(out.stdout)
    assert got == {"type": "pmsm_sysid/msg/NarxModel", "ny": 30, "fs": 500.0, "start": 2,
                   "frame": "pmsm", "terms": [["y(k-1)", 0.5, 0.01, 0.9],
                                              ["u(k-14)", 33.7, 0.99, 0.043]]}


# --------------------------------------------------------------------------- direct CDR


def _stamped(msgtype: str, header: object, x: float) -> object:
    t = JAZZY.types
    vec = t["geometry_msgs/msg/Vector3"]
    zero, one = vec(x=0.0, y=0.0, z=0.0), vec(x=x, y=0.0, z=0.0)
    if msgtype.endswith("WrenchStamped"):
        return t[msgtype](header=header,
                          wrench=t["geometry_msgs/msg/Wrench"](force=one, torque=zero))
    if msgtype.endswith("TwistStamped"):
        return t[msgtype](header=header,
                          twist=t["geometry_msgs/msg/Twist"](linear=one, angular=zero))
    return t[msgtype](header=header, point=t["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0))


@pytest.mark.parametrize("msgtype", ["geometry_msgs/msg/WrenchStamped",
                                     "geometry_msgs/msg/TwistStamped",
                                     "geometry_msgs/msg/PointStamped"])
def test_direct_cdr_equals_rosbags(msgtype: str) -> None:
    from pmsm_sysid.bagio.cdr import decode_stamped, encode_stamped

    rng = np.random.default_rng(11)
    for frame_len in range(0, 19):
        frame = "f" * frame_len
        ns = int(rng.integers(0, 2**31 * 10**9))  # Time.sec is int32
        x = float(rng.normal() * 10.0 ** rng.integers(-300, 300))
        msg = _stamped(msgtype, _header(ns, frame), x)
        ref = bytes(JAZZY.serialize_cdr(msg, msgtype))
        assert encode_stamped(msgtype, ns, frame, x) == ref
        assert decode_stamped(ref) == (ns, x)
    assert decode_stamped(b"\x00\x00\x00\x00" + bytes(40)) is None  # big-endian: not ours
    assert decode_stamped(b"\x00\x01\x00\x00" + bytes(8)) is None   # truncated



IDENTIFY_JSON = {
    "input": "thrust", "output": "speed", "sample_rate_hz": 500.0,
    "structure": {"ny": 30, "nu": 40, "degree": 2, "delay": 1, "n_candidates": 2556},
    "terms": [{"name": "u(k-14)", "estimate": 33.7, "std": 0.99, "err": 0.043},
              {"name": "y(k-1)u(k-10)", "estimate": -0.25, "std": None, "err": 0.001}],
    "validation": {"estimation": {"nmse": 0.01, "r2": 0.99},
                   "validation": {"nmse": 0.02, "r2": 0.98, "osa_r2": 0.999},
                   "correlation_tests": {k: {"max_abs": 0.05, "band": 0.062, "pass": k != "ue"}
                                         for k in ("ee", "ue", "u2e", "u2e2", "e_eu")}},
    "timing_ms": {"regressors": 1.0, "selection": 2.0, "total": 250.0}}
GFRF_JSON = {"sample_rate_hz": 500.0, "stable": True, "poles": [],
             "h1": {"peaks": [{"freq_hz": 16.5, "freq_norm": 0.033, "gain_db": 50.1}]},
             "h2": {"ridges": [{"kind": "f1+f2", "freq_hz": 16.5, "freq_norm": 0.033}]},
             "h3": {"ridges": []}}


def test_typed_messages_from_json(tmp_path: Path) -> None:
    from pmsm_sysid.bagio import BagRecorder
    from pmsm_sysid.bagio.schemas import (
        encode_model_msg,
        encode_ridges_msg,
        encode_validation_msg,
    )

    window = (2 * 10**9, 4 * 10**9 - 2_000_000)
    blobs = {"NarxModel": encode_model_msg(IDENTIFY_JSON, stamp_ns=5 * 10**9, window=window),
             "ValidationStats": encode_validation_msg(IDENTIFY_JSON["validation"],
                                                      stamp_ns=5 * 10**9, window=window),
             "GfrfRidges": encode_ridges_msg(GFRF_JSON, stamp_ns=6 * 10**9)}
    with BagRecorder(tmp_path / "typed", storage="mcap") as rec:
        for name, blob in blobs.items():
            rec.add_topic(f"/typed/{name}", f"pmsm_sysid/msg/{name}")
            rec.write(f"/typed/{name}", 7 * 10**9, blob)
    with AnyReader([tmp_path / "typed"]) as reader:  # decoded from the bag's own definitions
        msgs = {c.msgtype.split("/")[-1]: reader.deserialize(raw, c.msgtype)
                for c, _, raw in reader.messages()}
    m = msgs["NarxModel"]
    assert (m.ny, m.nu, m.degree, m.delay, m.n_candidates) == (30, 40, 2, 1, 2556)
    assert [(t.name, t.estimate, t.err) for t in m.terms] == [
        ("u(k-14)", 33.7, 0.043), ("y(k-1)u(k-10)", -0.25, 0.001)]
    assert np.isnan(m.terms[1].std) and m.fit_time_s == 0.25
    assert (m.window_end.sec, m.window_end.nanosec) == (3, 998_000_000)
    v = msgs["ValidationStats"]
    assert [t.name for t in v.correlation_tests] == ["ee", "ue", "u2e", "u2e2", "e_eu"]
    assert v.validation_osa_r2 == 0.999 and v.all_passed is False
    g = msgs["GfrfRidges"]
    assert g.stable and g.h1_peaks[0].gain_db == 50.1 and g.h2_ridges[0].kind == "f1+f2"
    assert np.isnan(g.h2_ridges[0].gain_db) and g.h3_ridges == []
    with pytest.raises(BagError, match="not an identify JSON model"):
        encode_model_msg({"terms": []}, stamp_ns=0)
