"""Sim-to-real discrepancy: locate, name, model and show the physics a plant leaves out.

Entry point: :func:`diagnose` (see :mod:`.diagnose` for the method). Pure numpy/scipy.
"""

from .diagnose import DiagnoseOptions, diagnose
from .result import DiagnoseResult, FoundEffect

__all__ = ["DiagnoseOptions", "DiagnoseResult", "FoundEffect", "diagnose"]
