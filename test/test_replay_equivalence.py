"""``replay BAG`` + the identification side gives the models ``identify`` gives offline.

The recording is replayed by the ``replay`` verb in its own process; the identifier and GFRF
nodes run as ``run --nodes identifier,gfrf`` composes them. Every window the identifier
fits (both outputs; position as its increments, ``--form difference``) is identified again
offline from the bag with ``--estimate a:b`` of that window: terms must be identical and
estimates equal to 1e-9.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant
from pmsm_sysid.core.selection.identify import FitConfig, identify_recording
from pmsm_sysid.core.terms.model import NarxModel, Structure

pytestmark = [pytest.mark.ros, pytest.mark.slow]
REPO = Path(__file__).resolve().parents[1]
N = 2500


def _bag(tmp_path: Path) -> Path:
    from pmsm_sysid.bagio import write_recording

    plant = load_plant(REPO / "plants" / "nominal_noisy.yaml")
    rec = simulate(plant, make_excitation("paper-speed", N, plant.sample_rate_hz, seed=3),
                   seed=3)
    path = tmp_path / "tone"
    write_recording(path, rec)
    return path


def test_replayed_bag_gives_the_offline_models(ros_context: Any, ros_env: int,
                                                tmp_path: Path) -> None:
    from pmsm_sysid.app import build_pipeline
    from pmsm_sysid.bagio import read_recording
    from pmsm_sysid.core.frequency.analysis import analyse_json

    bag = _bag(tmp_path)
    env = {**os.environ, "ROS_DOMAIN_ID": str(ros_env), "ROS_LOG_DIR": str(tmp_path / "log"),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    # a queue for every window of the run: none skipped even when this machine is busy
    with build_pipeline(["identifier", "gfrf"], context=ros_context,
                        identifier_params={"queue_size": 16},
                        gfrf_params={"orders": [1, 2], "queue_size": 32}) as pipe:
        replay = subprocess.Popen(
            [sys.executable, "-m", "pmsm_sysid.cli", "replay", str(bag), "--wait", "30"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 120
            pipe.run(until=lambda: replay.poll() is not None or time.monotonic() > deadline)
            pipe.run(until=lambda: pipe.identifier.engine.samples_received >= N
                     or time.monotonic() > deadline)
        finally:
            if replay.poll() is None:
                replay.kill()
            _, err = replay.communicate()
        assert replay.returncode == 0, err
        pipe.finish()
        s = pipe.summary()
        models = list(pipe.nodes["collector"].model_log)
        ridges = {r["model_id"]: r for r in pipe.nodes["collector"].ridges_log}

    assert s["samples_received"] == N and s["samples_dropped"] == 0
    assert s["samples_missing"] == 0 and s["windows_skipped"] == 0
    rec = read_recording(bag).recording
    # windows end on the grid every 250 samples once 1000 + 40 lag samples are in
    stops = sorted({m["window"]["stop_index"] for m in models})
    assert stops == [1250, 1500, 1750, 2000, 2250, 2500]
    assert len(models) == 2 * len(stops)
    for m in models:
        a, b = m["window"]["start_index"], m["window"]["stop_index"]
        st = m["structure"]
        cfg = FitConfig(structure=Structure(st["ny"], st["nu"], st["degree"], st["delay"]),
                        method=m["method"])
        ref = identify_recording(rec, output=m["output"], config=cfg, estimate=(a, b),
                                 validate=None, form=m["form"]).to_dict()
        assert [t["name"] for t in m["terms"]] == [t["name"] for t in ref["terms"]], m["model_id"]
        got, want = NarxModel.from_dict(m), NarxModel.from_dict(ref)
        np.testing.assert_allclose(got.estimates, want.estimates, rtol=1e-9, atol=0)
        np.testing.assert_allclose(got.err, want.err, rtol=1e-9, atol=1e-15)
        assert m["validation"]["estimation"]["r2"] == pytest.approx(
            ref["validation"]["estimation"]["r2"], rel=1e-9)
        if m["output"] != "speed":
            continue
        # and the GFRF node's ridges are those of the offline model
        assert m["model_id"] in ridges, (m["model_id"], s["gfrf"])
        r = ridges[m["model_id"]]
        offline = analyse_json(ref, orders=(1, 2)).to_dict()
        assert [p["freq_hz"] for p in r["h1"]["peaks"]] == pytest.approx(
            [p["freq_hz"] for p in offline["h1"]["peaks"]], abs=1e-6)

    # the identify verb itself, on the last speed window
    last = max((m for m in models if m["output"] == "speed"),
               key=lambda m: m["window"]["stop_index"])
    a, b = last["window"]["start_index"], last["window"]["stop_index"]
    out = tmp_path / "identify.json"
    proc = subprocess.run([sys.executable, "-m", "pmsm_sysid.cli", "identify", str(bag),
                           "--estimate", f"{a}:{b}", "--no-validate", "--method",
                           last["method"], "--json", str(out)],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    cli = json.loads(out.read_text())
    assert [t["name"] for t in cli["terms"]] == [t["name"] for t in last["terms"]]
    np.testing.assert_allclose([t["estimate"] for t in cli["terms"]],
                               [t["estimate"] for t in last["terms"]], rtol=1e-9, atol=0)
