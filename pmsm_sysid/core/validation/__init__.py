"""Model validation after Liu et al. (2005): one-step-ahead and model predicted output
(free run), fit metrics and the five correlation tests.
"""

from .correlation import (
    CorrelationTest,
    CorrelationTests,
    FitMetrics,
    correlation_tests,
    false_rejection_rate,
    fit_metrics,
    welch_psd,
    window_false_rejection_rate,
    xcorr,
)
from .prediction import FreeRun, free_run, k_step_ahead, one_step_ahead, simulate
from .windows import window_rate

__all__ = [
    "CorrelationTest", "CorrelationTests", "FitMetrics", "FreeRun", "correlation_tests",
    "false_rejection_rate", "fit_metrics", "free_run", "k_step_ahead", "one_step_ahead",
    "simulate", "welch_psd", "window_false_rejection_rate", "window_rate", "xcorr"
]
