"""Checks run before every NARX fit: never a silently wrong model.

* Non-finite samples -> DataError naming the signal, the count and the first index.
* Too short for the lags -> DataError naming the need: a structure with maximum lag L and
  p parameters needs at least L + 2p samples (p regression rows are the bare minimum for p
  unknowns; twice that leaves as many degrees of freedom as parameters for the residual).
* A constant input or output -> InsufficientExcitationError.
* Persistent excitation: the effective order of the input over the structure's input lags
  is the number of eigenvalues of U^T U (U = the nu lagged input columns) above 1e-2 of the
  largest, i.e. directions within 20 dB of the strongest. A single tone gives 2 (3 with a
  d.c. level), s tones give 2s; a band-limited input gives about 2 x bandwidth / fs x nu.
  Sensor noise on a recorded tone (5 N on a 50 N sine: about 30 dB down per direction) is
  not counted as excitation: it did not drive the plant. If that is below nu the fit is
  still made (it is the paper's single-tone protocol) but a warning says so: input-lag terms
  are then not unique and the model only describes responses to inputs like this one.
* Values so large that the selection sums overflow float64 ((p^T y)^2 ~ n^2 x^(2d+2) for a
  degree-d regressor p, beyond 1e300), or so small that they underflow (below 1e-300) ->
  DataError naming the signal: rescale it.
* A signal that sits at its extreme value in >= 1 % of the samples (and takes more than 16
  distinct values, so two-level inputs are exempt) -> a warning: saturated or clipped data
  are not what drove, or came out of, the plant.
* Stamps off one sampling grid (:func:`check_sampling`) -> DataError: lags across a gap, a
  clock jump or a rate change would pair samples that are not one period apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, InsufficientExcitationError
from ..terms.model import Structure

FloatArray = NDArray[np.float64]

PE_REL_EIG = 1e-2
OVERFLOW_LOG10 = 300.0  # largest log10 of a sum of squared regressors accepted
SATURATION_SHARE = 0.01  # share of samples at the extreme value that is called saturation
RATE_TOLERANCE = 0.05  # a window's median stamp step may differ this much from the period


@dataclass(frozen=True)
class DataCheck:
    """What the data support, and any warning about them."""

    n_samples: int
    n_rows: int
    pe_order: int  # effective persistent-excitation order over the input lags
    pe_required: int  # the number of input lags nu
    warnings: tuple[str, ...] = ()

    @property
    def pe_sufficient(self) -> bool:
        return self.pe_order >= self.pe_required

    def to_dict(self) -> dict[str, Any]:
        return {"n_samples": self.n_samples, "n_rows": self.n_rows, "pe_order": self.pe_order,
                "pe_required": self.pe_required, "pe_sufficient": self.pe_sufficient,
                "warnings": list(self.warnings)}


def _finite(name: str, x: FloatArray) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        raise DataError(
            f"'{name}' has {int(bad.sum())} non-finite samples "
            f"(first at index {int(np.argmax(bad))})"
        )


def _magnitude(signals: dict[str, FloatArray], degree: int) -> None:
    """DataError if the selection sums would overflow float64: (p^T y)^2 with p a degree-d
    regressor reaches n^2 x^(2d+2) for signals of magnitude x."""
    peaks = {k: float(np.max(np.abs(v))) if v.size else 0.0 for k, v in signals.items()}
    name = max(peaks, key=lambda k: peaks[k])
    peak, n = peaks[name], max(v.size for v in signals.values())
    if peak > 0 and (2 * degree + 2) * np.log10(peak) + 2 * np.log10(n) > OVERFLOW_LOG10:
        raise DataError(f"'{name}' reaches {peak:.3g}: too large for a degree-{degree} model "
                        "(its regressor sums overflow float64); rescale the signal")
    if peak > 0 and (2 * degree + 2) * np.log10(peak) < -OVERFLOW_LOG10:
        raise DataError(f"the signals reach only {peak:.3g}: too small for a degree-{degree} "
                        "model (its regressor sums underflow float64); rescale them")


def saturation(name: str, x: FloatArray) -> str | None:
    """A warning if x sits at its maximum or minimum in >= 1 % of the samples (module doc)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    if n < 100 or len(np.unique(x)) <= 16:
        return None
    for word, ext in (("maximum", float(np.max(x))), ("minimum", float(np.min(x)))):
        count = int(np.count_nonzero(x == ext))
        if count >= SATURATION_SHARE * n:
            return (f"{name} sits at its {word} {ext:.6g} in {count} of {n} samples "
                    f"({100.0 * count / n:.1f}%): saturated or clipped? Clipped data are not "
                    "what drove, or came out of, the plant")
    return None


def check_sampling(t: FloatArray, sample_rate_hz: float, label: str, first: int = 0) -> None:
    """DataError unless every stamp step of a window is within (0.5, 1.5) sample periods and
    their median within 5 % of one period.

    A longer step is a gap or a clock jump forward; a shorter one is a sample-rate change or
    stamps folded back by a clock jump (sorted in between); a median off the period is a
    stretch recorded at another rate. ``first`` is the index of t[0] in the recording, for
    the message."""
    steps = np.diff(np.asarray(t, dtype=np.float64)) * float(sample_rate_hz)
    bad = ~((steps > 0.5) & (steps < 1.5))
    if bad.any():
        k = int(np.argmax(bad))
        raise DataError(
            f"{label} is not evenly sampled: {int(bad.sum())} stamp step(s) off the "
            f"{sample_rate_hz:g} Hz grid, the first after sample {first + k} (t = {t[k]:.6g} s, "
            f"step {steps[k]:.3g} periods): a gap, clock jump or rate change; choose a range "
            "without one")
    med = float(np.median(steps)) if len(steps) >= 10 else 1.0
    if abs(med - 1.0) > RATE_TOLERANCE:
        raise DataError(
            f"{label} is sampled at {sample_rate_hz / med:.4g} Hz (median stamp step), the "
            f"recording at {sample_rate_hz:.4g} Hz: the sample rate changed; choose a range "
            "recorded at the recording's rate")


def pe_order(u: FloatArray, structure: Structure, u_lags: FloatArray | None = None) -> int:
    """Effective persistent-excitation order of u over the nu input lags (module doc).

    ``u_lags`` may pass the (rows x nu) lagged input columns when they exist already."""
    nu, lag = structure.nu, structure.max_lag
    if nu == 0:
        return 0
    if u_lags is None:
        n, d = len(u), structure.delay
        u_lags = np.stack([u[lag - d - j : n - d - j] for j in range(nu)], axis=1)
    eig = np.linalg.eigvalsh(u_lags.T @ u_lags)
    top = float(eig.max())
    return int(np.count_nonzero(eig > PE_REL_EIG * top)) if top > 0 else 0


def check_fit_data(
    y: FloatArray, u: FloatArray, structure: Structure, n_params: int,
    input_name: str = "input", output_name: str = "output",
    u_lags: FloatArray | None = None,
) -> DataCheck:
    """Raise on unusable data; return what the data support (with warnings)."""
    validate_fit_data(y, u, structure, n_params, input_name, output_name)
    return describe_fit_data(u, structure, input_name, u_lags)


def validate_fit_data(
    y: FloatArray, u: FloatArray, structure: Structure, n_params: int,
    input_name: str = "input", output_name: str = "output",
) -> None:
    """The raising half of :func:`check_fit_data`."""
    y = np.asarray(y, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if y.ndim != 1 or u.shape != y.shape:
        raise DataError(f"{output_name} and {input_name} must be 1-D of equal length "
                        f"(got {y.shape} and {u.shape})")
    _finite(output_name, y)
    _finite(input_name, u)
    _magnitude({output_name: y, input_name: u}, structure.degree)
    n, lag = len(y), structure.max_lag
    need = lag + 2 * n_params
    if n < need:
        raise DataError(f"{n} samples are too few: maximum lag {lag} and {n_params} parameters "
                        f"need at least {need} (lag + 2 x parameters)")
    if float(np.ptp(u)) == 0.0:
        raise InsufficientExcitationError(
            f"insufficient excitation: {input_name} is constant in the estimation data")
    if float(np.ptp(y[lag:])) == 0.0:
        raise InsufficientExcitationError(
            f"insufficient excitation: {output_name} is constant in the estimation data")


def describe_fit_data(
    u: FloatArray, structure: Structure, input_name: str = "input",
    u_lags: FloatArray | None = None, y: FloatArray | None = None,
    output_name: str = "output",
) -> DataCheck:
    """The non-raising half: persistent-excitation order and warnings."""
    n = len(u)
    order = pe_order(np.asarray(u, dtype=np.float64), structure, u_lags)
    warnings: list[str] = []
    if order < structure.nu:
        warnings.append(
            f"insufficient excitation: {input_name} is persistently exciting of order "
            f"{order} only (< nu = {structure.nu} input lags): input-lag terms are not "
            f"unique and the model holds for inputs like this one (e.g. a single tone gives "
            f"order 2)")
    for name, x in ((input_name, u), (output_name, y)):
        clipped = saturation(name, x) if x is not None else None
        if clipped:
            warnings.append(clipped)
    return DataCheck(n_samples=n, n_rows=n - structure.max_lag, pe_order=order,
                     pe_required=structure.nu, warnings=tuple(warnings))
