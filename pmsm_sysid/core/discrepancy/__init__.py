"""Sim-to-real discrepancy: a recording against a plant -- locate the mismatch, name the
physics the plant leaves out, model what no name explains, show the fit improve.

Entry point: :func:`diagnose` (see :mod:`.diagnose` for the method). The effects are fitted
by the plant-fitting stage (:mod:`pmsm_sysid.core.plantfit`). Pure numpy/scipy.
"""

from ..plantfit.found import FoundEffect
from .diagnose import DiagnoseOptions, diagnose
from .result import DiagnoseResult

__all__ = ["DiagnoseOptions", "DiagnoseResult", "FoundEffect", "diagnose"]
