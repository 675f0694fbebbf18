"""A run's cross-validated windows judged together: is their failure rate that of a
correct model?

The correlation tests (:mod:`.correlation`) reject a correct model in some windows by
chance: 4.1 % for white residuals by their own rule
(:func:`~.correlation.window_false_rejection_rate`); over one simulated hour of the default
live run 4.2 % of the position and 5.1 % of the speed windows failed (the speed residual keeps
a trace of the speed sensor's noise). A run's count of failed windows is therefore compared
with :data:`NULL_RATE`, 1 in 20, by a one-sided binomial test at :data:`LEVEL`, 1 %. The
windows of a live run overlap (a hop of 250 in 1000 samples), so their outcomes are not
quite independent: over 600 simulated seconds of the default run 16 of 60 failed speed
windows had a failed neighbour, against about 6 for independent windows; the verdict then
flagged 2 of 99 runs of 10 s, 0 of 22 of 30 s and 0 of 10 of 60 s
(``bench/validation_rate.py``).
"""

from __future__ import annotations

from typing import Any

# scipy.special at import, not at the first call: the identifier node judges its windows on
# its executor thread, where a first import would hold up the intake; and not scipy.stats,
# whose import (half a second, more on a busy machine) every live process would pay
from scipy import special

__all__ = ["LEVEL", "NULL_RATE", "window_rate"]

#: Share of windows whose cross-validation a correct model may fail (module doc).
NULL_RATE = 0.05
#: One-sided level of the binomial test of the failed windows against NULL_RATE.
LEVEL = 0.01


def window_rate(passed: int, made: int) -> dict[str, Any]:
    """The binomial test of a run's windows: ``p_value`` = P(X >= failed) for X ~
    Binomial(made, NULL_RATE); ``consistent`` with a correct model when it is >= LEVEL;
    ``judged`` is False when even every window failing could not reach LEVEL (too few).

    Example: 2 failed of 12 is what a correct model does (p = 0.12), 12 of 52 is not.

    >>> round(window_rate(10, 12)["p_value"], 2), window_rate(40, 52)["consistent"]
    (0.12, False)
    """
    failed = made - passed
    p_value = float(special.bdtrc(failed - 1, made, NULL_RATE)) if made and failed > 0 else 1.0
    return {"passed": passed, "windows": made, "failed": failed, "null_rate": NULL_RATE,
            "level": LEVEL, "p_value": p_value, "consistent": p_value >= LEVEL,
            "judged": made > 0 and NULL_RATE ** made < LEVEL}
