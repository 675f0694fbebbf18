"""The live diagnosis's work: a span of aligned samples -> ``ps.diagnose`` -> its JSON.

This module runs in the diagnosis node's worker process (:class:`LiveDiagnoser`, built there
once) and imports no ROS, so that process starts light. A :class:`DiagnoseJob` carries the
real span (a :class:`~pmsm_sysid.core.online.windows.Window` of the node's aligned inputs),
its sample rate, the options of this diagnosis and, with a simulator beside the drive, the
simulator's latest span. The result is the diagnose JSON (``ps.Diagnosis.to_dict()``, what
``pmsm-sysid diagnose --json`` writes for the same samples) plus:

* ``window``: ``seq``, ``start_stamp``/``end_stamp`` (s, the span's first and last sample),
  ``samples``, ``sample_rate_hz``, ``speed_derived``;
* ``sim_window``: the same for the simulator's span (with ``--diagnose-sim``);
* ``reference``: ``plant_file`` or ``sim_recording``; ``held_out``: what was held out;
* ``diagnosis_cpu_s``: CPU seconds of this diagnosis.

Held-out data: ``diagnose``'s own split, the last 30 % of the span. The previous span is not
used: it overlaps this one (by span − period) and, after a change of the drive, holds the old
plant, so it would refuse an effect that has just appeared.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from ..core.errors import OptionError
from ..core.online.windows import Window

HELD_OUT = "the last 30 % of the span (diagnose's own split)"


@dataclass(frozen=True)
class DiagnoseJob:
    """One diagnosis to run: the real span and, optionally, the simulator's span."""

    real: Window
    sample_rate_hz: float
    sim: Window | None = None
    sim_rate_hz: float = 0.0
    alpha: float = 1e-3
    min_share: float = 0.01
    replay: bool = True
    gfrf: bool = False


def window_block(w: Window, fs: float) -> dict[str, Any]:
    """Where a span lies: its sequence number, first and last stamp, samples and rate."""
    return {"seq": w.seq, "start_stamp": w.start_stamp, "end_stamp": w.end_stamp,
            "samples": w.stop_index - w.start_index, "sample_rate_hz": fs,
            "speed_derived": w.speed_derived}


class LiveDiagnoser:
    """``ps.diagnose`` of each job against ``plant`` (a ``ps.Plant``, read from the file
    ``plant_file``) or, when ``plant`` is None, against the simulator's span the job
    carries."""

    def __init__(self, plant: Any | None, plant_file: str = "") -> None:
        import pmsm_sysid as ps

        self._ps = ps
        self.plant, self.plant_file = plant, plant_file

    def __call__(self, job: DiagnoseJob) -> dict[str, Any]:
        ps = self._ps
        c0 = time.process_time()
        real = job.real.recording(job.sample_rate_hz, with_history=False)
        options = {"alpha": job.alpha, "min_share": job.min_share, "replay": job.replay,
                   "gfrf": job.gfrf}
        extra: dict[str, Any] = {"window": window_block(job.real, job.sample_rate_hz),
                                 "held_out": HELD_OUT}
        if self.plant is not None:
            found = ps.diagnose(self.plant, real, **options)
            extra.update(reference="plant_file", plant_file=self.plant_file)
        else:
            if job.sim is None:
                raise OptionError("no complete span of the simulator's inputs yet")
            sim = job.sim.recording(job.sim_rate_hz, with_history=False)
            found = ps.diagnose(None, real, sim=sim, **options)
            extra.update(reference="sim_recording",
                         sim_window=window_block(job.sim, job.sim_rate_hz))
        out: dict[str, Any] = {**found.to_dict(), **extra}
        out["diagnosis_cpu_s"] = time.process_time() - c0
        return out
