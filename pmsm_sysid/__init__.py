"""pmsm_sysid: identification, frequency analysis and sim-to-real diagnosis of a linear
permanent-magnet synchronous servo motor, after Liu, Lee, Wang, Uppala and Chen.

A library as well as a command-line tool (``pmsm-sysid``) and a set of ROS 2 nodes; the
Python API needs no ROS installation.

Example:
    >>> import pmsm_sysid as ps
    >>> rec = ps.read_bag("bags/paper_speed_nominal")        # or ps.simulate(...)
    >>> fit = ps.identify(rec, terms=10)                      # NARX model by OFR/ERR
    >>> peaks = ps.gfrf(fit).to_dict()["h1"]["peaks"]         # GFRFs, H1 peaks, ridges
    >>> diagnosis = ps.diagnose("plants/nominal.yaml", "bags/paper_speed_coulomb")

| name | what |
| --- | --- |
| `read_bag`, `write_bag`, `Recording` | rosbag2 recordings of thrust, speed and position |
| `simulate`, `Plant` | the motor model offline (`Plant.nominal()`, `Plant.from_yaml`) |
| `identify` → `Identification` | polynomial NARX by orthogonal forward regression |
| `gfrf` → `GfrfAnalysis` | generalized frequency response functions, peaks, ridges |
| `fit_plant` → `PlantFit` | the physical plant (mass, viscous, effects) of a recording |
| `diagnose` → `Diagnosis` | which physics a plant (or a simulator's recording) leaves out |
| `fleet` → `FleetResult` | many recordings on Dask: fitted plants, per-axis trends, alarms |
| `PmsmSysidError` | base of every error raised on bad input |

Each result's ``to_dict()`` is the JSON the matching ``pmsm-sysid`` verb writes.
Importing the package is light: numpy, scipy and rosbags load on first use of a name.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .core.errors import PmsmSysidError

__version__ = "0.1.0"

__all__ = [
    "Diagnosis", "FleetResult", "GfrfAnalysis", "Identification", "NarxModel", "Plant",
    "PlantFit", "PmsmSysidError", "Recording", "diagnose", "fit_plant", "fleet", "gfrf",
    "identify", "read_bag", "simulate", "write_bag",
]

if TYPE_CHECKING:
    from .api import (
        Diagnosis,
        FleetResult,
        GfrfAnalysis,
        Identification,
        NarxModel,
        Plant,
        PlantFit,
        Recording,
        diagnose,
        fit_plant,
        fleet,
        gfrf,
        identify,
        read_bag,
        simulate,
        write_bag,
    )


def __getattr__(name: str) -> Any:
    """Load the public names on first use (``import pmsm_sysid`` stays light)."""
    if name in __all__:
        value = getattr(importlib.import_module(".api", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
