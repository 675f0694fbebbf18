"""Structure selection and estimation: orthogonal forward regression with the error
reduction ratio (and its iterative variant), the checks run before every fit, and the
``identify`` pipeline from a recording to a validated model.
"""

from .datacheck import DataCheck, check_fit_data, describe_fit_data, validate_fit_data
from .identifiability import ExcitationSummary, excitation_summary, identifiability_block
from .identify import (
    FitConfig,
    IdentifyResult,
    NarxFit,
    ValidationReport,
    fit_narx,
    identify_recording,
    validate_narx,
)
from .iofr import IofrResult, iofr
from .ofr import OfrResult, frols, information_criterion, least_squares

__all__ = [
    "DataCheck", "ExcitationSummary", "FitConfig", "IdentifyResult", "IofrResult",
    "NarxFit", "OfrResult", "ValidationReport", "check_fit_data", "describe_fit_data",
    "excitation_summary", "fit_narx", "frols", "identifiability_block",
    "identify_recording", "information_criterion", "iofr", "least_squares",
    "validate_fit_data", "validate_narx"
]
