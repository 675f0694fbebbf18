"""diagnose refuses a recording with a gap (its derivatives, filters and replays need one
sampling grid): one line, exit 2, instead of a silently worse diagnosis."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from reliability_helpers import cli_error

from pmsm_sysid.bagio import read_recording, write_recording

REPO = Path(__file__).resolve().parents[1]


def test_diagnose_refuses_a_gapped_recording(tmp_path: Path, capsys: Any) -> None:
    rec = read_recording(REPO / "bags" / "paper_speed_nominal").recording
    keep = np.r_[0:2000, 2025:len(rec)]  # 25 samples lost: a 51 ms gap
    gapped = replace(rec, t=rec.t[keep], thrust=rec.thrust[keep], speed=rec.speed[keep],
                     position=rec.position[keep])
    bag = tmp_path / "gapped"
    write_recording(bag, gapped)
    cli_error(capsys, ["diagnose", "--plant", str(REPO / "plants" / "nominal.yaml"),
                       "--real", str(bag)], "not evenly sampled", "gap")
