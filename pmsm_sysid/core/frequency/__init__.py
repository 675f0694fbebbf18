"""Frequency analysis: generalized frequency response functions H1-H3 of a NARX model,
their ridges and poles, and the per-model analysis the GFRF node publishes.
"""

from .analysis import GfrfAnalysis, analyse, analyse_json
from .gfrf import Gfrf, to_hz, to_norm
from .message import MessageAnalyser, analyse_message
from .ridges import Peak, Pole, Ridge, h1_peaks, h2_ridges, h3_ridges, poles

__all__ = [
    "Gfrf", "GfrfAnalysis", "MessageAnalyser", "Peak", "Pole", "Ridge", "analyse",
    "analyse_json", "analyse_message", "h1_peaks", "h2_ridges", "h3_ridges", "poles",
    "to_hz", "to_norm"
]
