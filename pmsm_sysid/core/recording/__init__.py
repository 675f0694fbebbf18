"""Recordings of one drive axis: sampled thrust, speed and position; the stamp alignment
that turns three input streams into one recording (first stage of the data flow); the spans
of a long recording that the fitting stages use (:mod:`.spans`); and the Welch spectra and
peaks of sampled signals that later stages take (:mod:`.spectra`, NumPy alone).
"""

from .align import AlignReport, align_streams
from .signals import Recording, SpeedDeriver, check_finite, derive_speed, estimate_sample_rate
from .spans import MAX_SAMPLES, Excerpt, excerpt_of, plan_spans
from .spectra import find_peaks, welch

__all__ = [
    "MAX_SAMPLES", "AlignReport", "Excerpt", "Recording", "SpeedDeriver", "align_streams",
    "check_finite", "derive_speed", "estimate_sample_rate", "excerpt_of", "find_peaks",
    "plan_spans", "welch"
]
