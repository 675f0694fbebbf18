"""A run's cross-validated windows judged together: is their failure rate that of a
correct model?

The correlation tests (:mod:`.correlation`) reject a correct model in some windows by
chance: 4.1 % for white residuals by their own rule
(:func:`~.correlation.window_false_rejection_rate`); over one simulated hour of the default
live run 4.2 % of the position and 5.1 % of the speed windows failed (the speed residual keeps
a trace of the speed sensor's noise), and 3.8 % and 4.3 % over 400 simulated seconds cut at
20 grid phases. A run's count of failed windows is therefore compared with :data:`NULL_RATE`,
1 in 20, by a one-sided test at :data:`LEVEL`, 1 %.

The windows of a live run overlap (by default a hop of 250 in 1000 samples), so their
outcomes are not independent: two windows that share most of their samples tend to pass or
fail together, and a binomial test that counts them as independent trials rejects correct
models too often (on the default run, 1.1 % of 10 s runs instead of at most 1 %, and the
default run's own 10 s as it falls on the grid, 1.6 %; far more with a small hop). The count
is judged as quasi-binomial: its variance is the binomial one times the dispersion

    phi(n, s) = 1 + (2 / n) sum_{k=1}^{n-1} (n - k) rho(k s),

the exact variance of a sum of ``n`` equally likely outcomes whose correlation at a shift
of ``d`` windows is ``rho(d)`` (``s`` = hop / window), and the test is the binomial one on
``failed / phi`` of ``n / phi`` windows (its tail continued to fractional counts by the
regularised incomplete beta function). :data:`OUTCOME_CORRELATION` is ``rho``, the larger of
the speed and position outputs' correlations measured on the default run over 20 grid phases
(``bench/validation_rate.py --phases``); windows more than 1.6 windows apart are independent
(the tail before it is the excitation's 4 s period), and for windows that far apart the test
is the plain binomial one. On 2400 simulated seconds beyond those the table was measured on,
the test said FAIL for 3 of 399 10 s runs at the default hop and for 4 of 399 at a hop of 50
(the binomial test: 6 and 38).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

# scipy.special at import, not at the first call: the identifier node judges its windows on
# its executor thread, where a first import would hold up the intake; and not scipy.stats,
# whose import (half a second, more on a busy machine) every live process would pay
from scipy import special

__all__ = ["DEFAULT_SHIFT", "LEVEL", "NULL_RATE", "OUTCOME_CORRELATION", "dispersion",
           "grid_shift", "window_rate"]

#: Share of windows whose cross-validation a correct model may fail (module doc).
NULL_RATE = 0.05
#: One-sided level of the test of the failed windows against NULL_RATE.
LEVEL = 0.01
#: The identifier's default hop over its default window (250 / 1000 samples).
DEFAULT_SHIFT = 0.25
#: Correlation of two windows' pass/fail outcomes by their shift in windows (start
#: difference / window length), linear in between, 0 from the last shift on (module doc).
OUTCOME_CORRELATION = (
    (0.0, 1.0), (0.05, 0.37), (0.1, 0.21), (0.15, 0.14), (0.2, 0.12), (0.25, 0.11),
    (0.3, 0.10), (0.4, 0.07), (0.5, 0.06), (0.6, 0.045), (0.75, 0.045), (1.0, 0.03),
    (1.25, 0.03), (1.5, 0.02), (1.6, 0.0))
_SHIFTS, _RHO = (np.array(c, dtype=np.float64) for c in zip(*OUTCOME_CORRELATION, strict=True))


def grid_shift(grid: Mapping[str, Any] | None) -> float:
    """The hop over the window of an identifier's window grid (``{"window": ..., "hop":
    ...}``, as the run summary's ``window_grid``), or :data:`DEFAULT_SHIFT` without one."""
    if grid is None:
        return DEFAULT_SHIFT
    try:
        shift = float(grid["hop"]) / float(grid["window"])
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return DEFAULT_SHIFT
    return shift if shift > 0 else DEFAULT_SHIFT


def dispersion(made: int, shift: float = DEFAULT_SHIFT,
               table: Sequence[tuple[float, float]] | None = None) -> float:
    """phi(made, shift) of the module doc: the variance of a run's failed-window count over
    the binomial variance, for ``made`` windows ``shift`` windows apart (hop / window), with
    rho from ``table`` ((shift, rho) pairs in increasing shift; default
    :data:`OUTCOME_CORRELATION`).

    >>> round(dispersion(12), 2), dispersion(12, shift=2.0)
    (1.46, 1.0)
    """
    if not shift > 0:
        raise ValueError(f"shift must be > 0 windows (hop / window), got {shift}")
    shifts, rhos = (_SHIFTS, _RHO) if table is None else (
        np.array(c, dtype=np.float64) for c in zip(*table, strict=True))
    k = np.arange(1, made, dtype=np.float64)
    rho = np.interp(k * shift, shifts, rhos, right=0.0)
    return 1.0 + 2.0 * float(np.sum((made - k) * rho)) / made if made > 1 else 1.0


def window_rate(passed: int, made: int, shift: float = DEFAULT_SHIFT) -> dict[str, Any]:
    """The test of a run's windows (``shift``: the hop over the window): ``p_value`` =
    P(X >= failed) for X the failed count of a correct model (quasi-binomial, module doc);
    ``consistent`` with a correct model when it is >= LEVEL; ``judged`` is False when even
    every window failing could not reach LEVEL (too few).

    Example: 2 failed of 12 is what a correct model does (p = 0.19), 12 of 52 is not.

    >>> round(window_rate(10, 12)["p_value"], 2), window_rate(40, 52)["consistent"]
    (0.19, False)
    """
    failed = made - passed
    phi = dispersion(made, shift)
    k, n = failed / phi, made / phi
    # P(X >= k) of Binomial(n, p) = I_p(k, n - k + 1), for fractional k and n as well
    p_value = float(special.betainc(k, n - k + 1.0, NULL_RATE)) if made and failed > 0 else 1.0
    return {"passed": passed, "windows": made, "failed": failed, "null_rate": NULL_RATE,
            "level": LEVEL, "dispersion": phi, "p_value": p_value,
            "consistent": p_value >= LEVEL, "judged": made > 0 and NULL_RATE ** n < LEVEL}
