"""The public Python API, re-exported at the top level as ``import pmsm_sysid as ps``.

Modules: :mod:`.recordings` (bags), :mod:`.simulation`, :mod:`.identification`,
:mod:`.frequency` (GFRFs), :mod:`.plantfit` (a physical plant from a recording),
:mod:`.diagnosis` (sim-to-real), :mod:`.fleet_batch` (many recordings on Dask, per-axis
trends; the ``[fleet]`` extra). No ROS installation is needed.

Each name is loaded from its module on first use, so that a program (or a ``pmsm-sysid``
verb) that identifies a model does not import what a diagnosis needs: measured on
``pmsm-sysid identify`` of a 10 s recording, importing every module first cost 0.6 s of
its 0.9 s of CPU (SciPy's signal, stats and optimize packages among them).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ..core.errors import PmsmSysidError

if TYPE_CHECKING:
    from ..core.frequency.analysis import GfrfAnalysis
    from ..core.physics.plant import Plant
    from ..core.recording.signals import Recording
    from ..core.terms.model import NarxModel
    from .diagnosis import Diagnosis, diagnose
    from .fleet_batch import FleetResult, fleet
    from .frequency import gfrf
    from .identification import Identification, identify
    from .plantfit import PlantFit, fit_plant
    from .recordings import read_bag, write_bag
    from .simulation import simulate

#: public name -> the module (relative to this package) that defines it
_WHERE = {
    "GfrfAnalysis": "..core.frequency.analysis", "Plant": "..core.physics.plant",
    "Recording": "..core.recording.signals", "NarxModel": "..core.terms.model",
    "Diagnosis": ".diagnosis", "diagnose": ".diagnosis",
    "FleetResult": ".fleet_batch", "fleet": ".fleet_batch", "gfrf": ".frequency",
    "Identification": ".identification", "identify": ".identification",
    "PlantFit": ".plantfit", "fit_plant": ".plantfit",
    "read_bag": ".recordings", "write_bag": ".recordings", "simulate": ".simulation",
}

__all__ = [
    "Diagnosis", "FleetResult", "GfrfAnalysis", "Identification", "NarxModel", "Plant",
    "PlantFit", "PmsmSysidError", "Recording", "diagnose", "fit_plant", "fleet", "gfrf",
    "identify", "read_bag", "simulate", "write_bag",
]


def __getattr__(name: str) -> Any:
    """Load a public name from its module on first use (module doc)."""
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(where, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
