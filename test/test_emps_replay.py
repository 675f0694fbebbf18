"""A real recording end to end: the EMPS rig (../shared; 1 kHz, position only, closed loop).

The README's walkthrough as a test: ``import-mat``, ``replay`` (its own process) into the
identifier and GFRF nodes, offline ``identify`` of the same windows, ``diagnose``. The
recording has no speed topic, so the identifier derives speed from position live, by the
same causal differentiator the offline readers use; every window it fits (speed and
position) must be the model ``identify`` finds offline on the same samples: the same terms,
estimates equal to 1e-9. A slice of the recording keeps the replay short (4 s of its own
pace, at half speed); ``identify`` runs in this process. The import and ``diagnose`` of the
whole recording are those test_emps_diagnose.py checks, made once for both (conftest's
``emps_diagnosis``, the two files in one xdist group).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import EMPS_MAT, EmpsDiagnosis
from replay_helpers import (
    assert_identify_verb_agrees,
    assert_live_equals_offline,
    replay_into_pipeline,
)

# the import and its diagnosis: made once for this file and test_emps_diagnose.py (conftest)
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("emps")]
REPO = Path(__file__).resolve().parents[1]
START, STOP = 10_000, 14_000  # the slice replayed (samples of the 24841)


def _slice(full: Path, out: Path) -> None:
    from pmsm_sysid.bagio import read_recording, write_recording

    rec = read_recording(full).recording
    write_recording(out, rec.window(START, STOP))  # speed derived: no speed topic written


def test_emps_walkthrough_live_equals_offline(ros_context: Any, ros_env: int,
                                              emps_diagnosis: EmpsDiagnosis,
                                              tmp_path: Path) -> None:
    from pmsm_sysid.bagio import read_recording

    assert EMPS_MAT.is_file(), f"{EMPS_MAT} missing"
    full, part = emps_diagnosis.bag, tmp_path / "emps_slice"
    assert emps_diagnosis.imported.returncode == 0, emps_diagnosis.imported.stderr
    _slice(full, part)
    env = {**os.environ, "ROS_DOMAIN_ID": str(ros_env), "ROS_LOG_DIR": str(tmp_path / "log"),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    live = tmp_path / "live"
    # half its own pace: a subscriber starved for up to 2 s (a busy machine) still loses
    # nothing from its queue of 1000 messages
    run = replay_into_pipeline(part, env, ros_context, STOP - START, record=str(live),
                               replay_args=("--wait", "60", "--subscribers", "2",
                                            "--rate", "0.5", "--json", "-"),
                               identifier_params={"queue_size": 64},
                               gfrf_params={"orders": [1], "queue_size": 64})
    s, models, replayed = run.summary, run.models, json.loads(run.replay_out)

    # the replay says what it published and that the identifier listened
    assert replayed["topics"]["/pmsm/position"] == STOP - START
    assert replayed["subscribers"]["/pmsm/position"] == 2  # the identifier and the recorder
    assert replayed["subscribers"]["/pmsm/thrust"] == 2
    # the run says what came and what did not, and that speed is derived
    assert s["samples_received"] == STOP - START and s["samples_dropped"] == 0
    assert s["samples_missing"] == 0 and s["windows_skipped"] == 0
    assert s["speed_derived"] is True
    assert s["record_samples_lost"] == 0  # no speed topic is no loss: it never existed
    ins = s["inputs"]
    assert ins["missing"] == ["/pmsm/speed"] and ins["problem"] is None
    assert ins["arrived"]["/pmsm/position"]["rate_hz"] == pytest.approx(1000.0, rel=1e-4)

    rec = read_recording(part).recording
    assert rec.speed_derived
    # the recording of the run holds the inputs as replayed and every model published
    assert len(read_recording(live).recording) == STOP - START
    sys.path.insert(0, str(REPO / "scripts"))
    from live_vs_offline import live_models

    assert len(live_models(str(live))) == len(models)
    outputs = {m["output"] for m in models}
    assert outputs == {"speed", "position"}
    n_windows = len({m["window"]["stop_index"] for m in models})
    assert n_windows >= 10 and len(models) == 2 * n_windows
    for m in models:
        # live indices are on the stamp grid; the offline index of a window is its stamp's
        a = int(np.searchsorted(rec.t, m["window"]["start_stamp"] - 1e-7))
        b = a + m["window"]["n_samples"]
        assert rec.t[b - 1] == pytest.approx(m["window"]["end_stamp"], abs=1e-9)
        assert m["speed_derived"] is (m["output"] == "speed")
        assert_live_equals_offline(m, rec, a, b)

    # the identify verb on the last speed window, then diagnose on the whole recording
    last = max((m for m in models if m["output"] == "speed"),
               key=lambda m: m["window"]["end_stamp"])
    a = int(np.searchsorted(rec.t, last["window"]["start_stamp"] - 1e-7))
    cli = assert_identify_verb_agrees(part, last, a, env, tmp_path / "identify.json")
    assert cli["speed_derived"] is True
    assert emps_diagnosis.diagnosed.returncode == 0, emps_diagnosis.diagnosed.stderr
    named = {e["name"]: e for e in json.loads(emps_diagnosis.json.read_text())["effects"]}
    assert named["coulomb_friction"]["params"]["amplitude_n"] == pytest.approx(20.39, rel=0.05)
    assert named["force_offset"]["params"]["amplitude_n"] == pytest.approx(-3.16, rel=0.10)
