"""Recordings of one drive axis: sampled thrust, speed and position, and the stamp
alignment that turns three input streams into one recording (first stage of the data flow).
"""

from .align import AlignReport, align_streams
from .signals import Recording, SpeedDeriver, check_finite, derive_speed, estimate_sample_rate

__all__ = [
    "AlignReport", "Recording", "SpeedDeriver", "align_streams", "check_finite",
    "derive_speed", "estimate_sample_rate"
]
