"""Known polynomial NARX systems for the identification tests (independent of the package's
prediction code: a plain loop over the terms written here)."""

from __future__ import annotations

import numpy as np
from scipy import signal

from pmsm_sysid.core.terms.model import Structure, Term

LINEAR = {"y(k-1)": 0.5, "y(k-2)": -0.3, "u(k-1)": 1.0, "u(k-2)": 0.4}
# The example: plain FROLS (and SysIdentPy) pick u(k-2) instead of y(k-2).
QUADRATIC = {"y(k-1)": 0.6, "y(k-2)": -0.2, "u(k-1)": 0.8, "y(k-1)u(k-2)": 0.25,
             "u(k-2)^2": -0.3}
CUBIC = {"y(k-1)": 0.5, "y(k-2)": -0.2, "u(k-1)": 0.8, "u(k-1)^3": 0.2,
         "y(k-1)^2u(k-2)": -0.1, "y(k-2)u(k-1)": 0.15}
WITH_CONSTANT = {"const": 0.7, "y(k-1)": 0.4, "u(k-1)": 1.2, "y(k-1)u(k-1)": 0.2}


def simulate(coeffs: dict[str, float], u: np.ndarray, noise_std: float = 0.0,
             seed: int = 0) -> np.ndarray:
    """y(k) = sum_c theta_c term_c(k) + e(k), e white Gaussian (equation error), y(<L) = 0."""
    rng = np.random.default_rng(seed)
    terms = [(Term.parse(n), float(v)) for n, v in coeffs.items()]
    lag = max((lg for t, _ in terms for _, lg in t.factors), default=1)
    e = noise_std * rng.standard_normal(len(u))
    y = np.zeros(len(u))
    for k in range(lag, len(u)):
        acc = 0.0
        for t, th in terms:
            v = th
            for var, lg in t.factors:
                v *= y[k - lg] if var == "y" else u[k - lg]
            acc += v
        y[k] = acc + e[k]
    return y


def white_input(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, n)


def coloured_input(n: int, seed: int = 0, pole: float = 0.5) -> np.ndarray:
    """AR(1)-filtered Gaussian noise (the input on which greedy FROLS goes wrong)."""
    x = np.random.default_rng(seed).standard_normal(n)
    return np.asarray(signal.lfilter([1.0], [1.0, -pole], x))


def names(coeffs: dict[str, float]) -> set[str]:
    return {Term.parse(n).name for n in coeffs}


def structure_for(degree: int, lags: int = 2, constant: bool = True) -> Structure:
    return Structure(ny=lags, nu=lags, degree=degree, delay=1, constant=constant)
