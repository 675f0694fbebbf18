"""Output error: replay the recorded thrust through a plant over short horizons.

Free-run simulation of a recording is only meaningful open loop: a closed-loop recording
(EMPS) holds its position by feedback, and the open-loop replay of its thrust drifts away
at the first unmodelled newton. So the replay restarts from the measured position and speed
every ``horizon_s`` (the lag state settled, the delay line kept) and the speed error is
scored over every horizon. The plant's noise and quantisation blocks are switched off: the
replay is the model's prediction, not another noisy draw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..physics import MotorSimulator
from ..plant import Plant
from ..signals import Recording
from ..validation import fit_metrics

FloatArray = NDArray[np.float64]

HORIZON_S = 0.25


@dataclass(frozen=True)
class Replay:
    """Speed replayed in horizons, the measured speed, and the NRMSE between them."""

    speed: FloatArray
    measured: FloatArray
    horizon_s: float
    nrmse: float


def replay(plant: Plant, rec: Recording, horizon_s: float = HORIZON_S) -> Replay:
    """Replay ``rec.thrust`` through ``plant`` (noise off), restarting every horizon."""
    clean = replace(plant, noise=None, quantisation=None, sample_rate_hz=rec.sample_rate_hz)
    n = len(rec)
    h = max(2, round(horizon_s * rec.sample_rate_hz))
    sim = MotorSimulator(clean, seed=0, x0=float(rec.position[0]), v0=float(rec.speed[0]))
    out = np.empty(n)
    for k in range(n):
        if k % h == 0:
            sim.set_state(float(rec.position[k]), float(rec.speed[k]))
        out[k] = sim.state.speed_mps
        if not math.isfinite(out[k]):
            out[k:] = np.nan
            break
        sim.advance(float(rec.thrust[k]))
    return Replay(out, rec.speed, h / rec.sample_rate_hz, fit_metrics(rec.speed, out).nrmse)
