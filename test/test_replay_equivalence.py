"""``replay BAG`` + the identification side gives the models ``identify`` gives offline.

The recording is replayed by the ``replay`` verb in its own process; the identifier and GFRF
nodes run as ``run --nodes identifier,gfrf`` composes them. Every window the identifier
fits (both outputs; position as its increments, ``--form difference``) is identified again
offline from the bag with ``--estimate a:b`` of that window: terms must be identical and
estimates equal to 1e-9.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest
from replay_helpers import (
    assert_identify_verb_agrees,
    assert_live_equals_offline,
    replay_into_pipeline,
)

from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import load_plant

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
    from pmsm_sysid.bagio import read_recording
    from pmsm_sysid.core.frequency.analysis import analyse_json

    bag = _bag(tmp_path)
    env = {**os.environ, "ROS_DOMAIN_ID": str(ros_env), "ROS_LOG_DIR": str(tmp_path / "log"),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    # a queue for every window of the run: none skipped even when this machine is busy
    run = replay_into_pipeline(bag, env, ros_context, N, replay_args=("--wait", "30"),
                               deadline_s=120, identifier_params={"queue_size": 16},
                               gfrf_params={"orders": [1, 2], "queue_size": 32})
    s, models, ridges = run.summary, run.models, run.ridges

    assert s["samples_received"] == N and s["samples_dropped"] == 0
    assert s["samples_missing"] == 0 and s["windows_skipped"] == 0
    rec = read_recording(bag).recording
    # windows end on the grid every 250 samples once 1000 + 40 lag samples are in
    stops = sorted({m["window"]["stop_index"] for m in models})
    assert stops == [1250, 1500, 1750, 2000, 2250, 2500]
    assert len(models) == 2 * len(stops)
    for m in models:
        a, b = m["window"]["start_index"], m["window"]["stop_index"]
        ref = assert_live_equals_offline(m, rec, a, b)
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
    a = last["window"]["start_index"]
    assert_identify_verb_agrees(bag, last, a, env, tmp_path / "identify.json")
