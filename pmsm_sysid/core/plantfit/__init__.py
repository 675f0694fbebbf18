"""A physical plant from a recording: equation-error data and a library of named effects.

The force residual of inverse dynamics against a reference plant (:mod:`.kinematics`,
parallel-filtered, with instruments for the mass and viscous terms), a library of
interpretable effects (:mod:`.library`), forward selection by ERR with prewhitened F-tests
(:mod:`.select`, :mod:`.stats`), nonlinear refinement and held-out confirmation
(:mod:`.estimate`, :mod:`.modelling`), and the effects as plant-file blocks
(:mod:`.translate`). :func:`.fit.fit_effects` runs the whole stage. Pure numpy/scipy.
"""

from .fit import EffectsFit, FitOptions, Segments, fit_effects, segments
from .found import FoundEffect

__all__ = ["EffectsFit", "FitOptions", "FoundEffect", "Segments", "fit_effects", "segments"]
