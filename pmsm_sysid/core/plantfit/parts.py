"""Equation-error data of a recording used in parts (spans of a long one).

Each part is a contiguous recording; its equation data are built as for any recording
(:func:`.kinematics.equation_data`: differences, parallel filter, edges trimmed, decimated,
instruments) and the parts are put end to end. Only what describes the noise is pooled
over all parts: the smoothed speed's noise and its deconvolved distribution (the friction
calibration, :mod:`.calibration`), so every part's friction regressors see the same prior.
Nothing is filtered across the gap between two parts: :class:`.kinematics.EquationData`
filters, pairs and trims within each part (its ``parts``), so a column of the joined data
equals the parts' own columns, concatenated.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

import numpy as np

from ..errors import DiagnoseError
from ..physics.plant import SIGN_SMOOTHING_MPS, Plant
from ..recording.spans import Parts, as_parts
from .calibration import SpeedPrior
from .kinematics import (
    EquationData,
    FilterSpec,
    _interval_ends,
    choose_filter,
    equation_data,
    smoothed_speed_noise,
)
from .zerophase import butter_sos

#: Fields that describe the filter or the whole data, the same for every part.
SHARED = ("sos", "parts")


def joined(datas: list[EquationData]) -> EquationData:
    """One-part equation data put end to end (see the module doc)."""
    if len(datas) == 1:
        return datas[0]
    first = datas[0]
    values: dict[str, Any] = {}
    for f in fields(EquationData):
        got = [getattr(d, f.name) for d in datas]
        if f.name == "inst" and got[0] is not None:  # one basis per part
            values[f.name] = tuple(q for d in got for q in d)
        elif f.name in SHARED or not isinstance(got[0], np.ndarray):
            values[f.name] = got[0]
        else:
            values[f.name] = np.concatenate(got)
    if any(d.parts for d in datas) or any(d.mode != first.mode or d.filt != first.filt
                                          for d in datas):
        raise DiagnoseError("equation data of parts must be single parts with one filter")
    return replace(first, **{**values, "parts": tuple(len(d.cmd) for d in datas)})


def equation_data_parts(plant: Plant, rec: Parts, filt: FilterSpec | None = None,
                        mode: str | None = None, closed_loop: bool = False,
                        thrust_gap: int = 0) -> EquationData:
    """:func:`.kinematics.equation_data` of a recording or of the parts of one (joined)."""
    parts = as_parts(rec)
    if len(parts) == 1:
        return equation_data(plant, parts[0], filt, mode, closed_loop, thrust_gap=thrust_gap)
    fs = parts[0].sample_rate_hz
    mode = mode or ("position" if parts[0].speed_derived else "speed")
    spec = filt or choose_filter([p.speed for p in parts], fs)
    sos = butter_sos(spec.order, spec.cutoff_hz, fs)
    noise = smoothed_speed_noise(parts, mode, sos)
    ends = [np.concatenate(_interval_ends(p, mode, sos)) for p in parts]
    prior = SpeedPrior.from_speeds(np.concatenate(ends), noise, SIGN_SMOOTHING_MPS)
    return joined([equation_data(plant, p, spec, mode, closed_loop, (noise, prior),
                                 thrust_gap) for p in parts])


__all__ = ["equation_data_parts", "joined"]
