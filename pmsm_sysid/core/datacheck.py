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
  not counted as excitation: it did not drive the plant. If that is below nu the fit is still made (it is the paper's
  single-tone protocol) but a warning says so: input-lag terms are then not unique and the
  model only describes responses to inputs like this one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import DataError, InsufficientExcitationError
from .model import Structure

FloatArray = NDArray[np.float64]

PE_REL_EIG = 1e-2


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
    n, lag = len(y), structure.max_lag
    need = lag + 2 * n_params
    if n < need:
        raise DataError(f"{n} samples are too few: maximum lag {lag} and {n_params} parameters "
                        f"need at least {need} (lag + 2 x parameters)")
    if float(np.ptp(u)) == 0.0:
        raise InsufficientExcitationError(
            f"{input_name} is constant in the estimation data: nothing excites the system")
    if float(np.ptp(y[lag:])) == 0.0:
        raise InsufficientExcitationError(f"{output_name} is constant in the estimation data")


def describe_fit_data(
    u: FloatArray, structure: Structure, input_name: str = "input",
    u_lags: FloatArray | None = None,
) -> DataCheck:
    """The non-raising half: persistent-excitation order and warnings."""
    n = len(u)
    order = pe_order(np.asarray(u, dtype=np.float64), structure, u_lags)
    warnings: list[str] = []
    if order < structure.nu:
        warnings.append(
            f"{input_name} is persistently exciting of order {order} only (< nu = {structure.nu} "
            f"input lags): input-lag terms are not unique and the model holds for inputs like "
            f"this one (e.g. a single tone gives order 2)")
    return DataCheck(n_samples=n, n_rows=n - structure.max_lag, pe_order=order,
                     pe_required=structure.nu, warnings=tuple(warnings))
