"""The public Python API, re-exported at the top level as ``import pmsm_sysid as ps``.

Modules: :mod:`.recordings` (bags), :mod:`.simulation`, :mod:`.identification`,
:mod:`.frequency` (GFRFs), :mod:`.plantfit` (a physical plant from a recording),
:mod:`.diagnosis` (sim-to-real), :mod:`.fleet_batch` (many recordings on Dask, per-axis
trends; the ``[fleet]`` extra). No ROS installation is needed.
"""

from ..core.errors import PmsmSysidError
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

__all__ = [
    "Diagnosis", "FleetResult", "GfrfAnalysis", "Identification", "NarxModel", "Plant",
    "PlantFit", "PmsmSysidError", "Recording", "diagnose", "fit_plant", "fleet", "gfrf",
    "identify", "read_bag", "simulate", "write_bag",
]
