"""Online identification without ROS: stamp alignment of streamed samples, windows, the
fit worker processes, the per-window tracker and the change detector behind ``run``, and
the spans in seconds of its live diagnosis.
"""

from .change import ChangeConfig, ChangeDecision, ChangeDetector
from .engine import EngineConfig, EngineStats, OnlineEngine
from .fitqueue import FitWorker, LatestQueue
from .history import RunHistory
from .inputs import InputAligner, InputReport
from .livesim import simulated_windows
from .monitoring import SysIdView, TopicStats
from .spans import LatestSpan, SpanSizer
from .streaming import Sample, StampAligner
from .tracker import TrackerConfig, WindowResult, WindowTracker
from .windows import Window, WindowScheduler
from .workerproc import ProcessWorker, WorkerDied

__all__ = [
    "ChangeConfig", "ChangeDecision", "ChangeDetector", "EngineConfig", "EngineStats",
    "FitWorker", "InputAligner", "InputReport", "LatestQueue", "LatestSpan", "OnlineEngine",
    "ProcessWorker", "RunHistory", "Sample", "SpanSizer", "StampAligner", "SysIdView",
    "TopicStats",
    "TrackerConfig", "Window", "WindowResult", "WindowScheduler", "WindowTracker",
    "WorkerDied", "simulated_windows"
]
