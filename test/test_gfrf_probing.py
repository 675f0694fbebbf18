"""Harmonic probing: GFRFs against the spectral lines of the simulated NARX model itself.

For u(k) = A cos(2 pi f1 k) + B cos(2 pi f2 k) the steady-state output of a stable NARX model
holds, at the combination frequency sum_i m_i f_i of order n = sum m_i, the complex line
(n! / prod m_i!) prod (A_i/2)^m_i H_n^sym(f.., f.., ...) plus terms of order n + 2 and above.
So the line at f1+f2 has amplitude A B |H2(f1, f2)|, at 2f (A^2/2)|H2(f, f)|, at 3f
(A^3/4)|H3(f, f, f)|, at 2f1-f2 (3/4) A^2 B |H3(f1, f1, -f2)|, at 4f (A^4/8)|H4|.
Frequencies sit on exact FFT bins of one period P, transients are discarded, and amplitudes
are small enough that the order n + 2 contamination is < 1e-4 relative (checked by halving).
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.terms.model import NarxModel

P = 2048                     # samples per period of the steady state
M1, M2 = 61, 157             # FFT bins of the two tones (f = m / P)
TABLE2 = {  # seed Table 2 with the stable reading y(k-18) = -0.090082
    "u(k-14)": 33.710, "y(k-1)": 0.31254, "y(k-14)": -0.090502, "y(k-30)": 0.13787,
    "y(k-33)u(k-21)": 0.38805, "y(k-23)": -0.10185, "y(k-5)": 0.096491, "y(k-26)": 0.10947,
    "y(k-18)": -0.090082, "y(k-9)": -0.11602, "y(k-6)": 0.086075, "y(k-2)": 0.091110,
    "y(k-7)y(k-33)": -0.0033757, "y(k-3)y(k-32)": -0.0034004, "y(k-16)y(k-36)": -0.0013394,
}
RICH = {  # lags > 1, quadratic and cubic cross terms of every kind
    "y(k-1)": 1.1, "y(k-2)": -0.4, "u(k-2)": 0.7, "u(k-4)": 0.3,
    "u(k-1)u(k-3)": 0.25, "y(k-2)u(k-1)": -0.2, "y(k-1)y(k-3)": 0.15,
    "u(k-2)^3": 0.1, "y(k-1)u(k-1)u(k-3)": 0.08, "y(k-1)y(k-2)u(k-2)": -0.05,
    "y(k-3)^3": 0.03, "y(k-2)^2u(k-3)": 0.04,
}
TOY = {"y(k-1)": 0.6, "u(k-1)": 1.3, "u(k-1)^2": 0.4, "y(k-1)u(k-1)": -0.7,
       "y(k-1)^2": 0.25, "u(k-1)^3": 0.9}
MODELS = {"toy": (TOY, 5e-4, P), "rich": (RICH, 5e-4, P), "table2": (TABLE2, 2e-5, 3 * P)}


def simulate_narx(coefs: dict[str, float], u: np.ndarray) -> np.ndarray:
    """Plain loop over the model's terms (independent of core/gfrf)."""
    model = NarxModel.from_terms(coefs)
    terms = [(float(c), t.factors) for t, c in zip(model.terms, model.estimates, strict=True)]
    lag = model.max_lag
    y = np.zeros(len(u) + lag)
    uu = np.concatenate((np.zeros(lag), u))
    for k in range(lag, len(y)):
        acc = 0.0
        for c, factors in terms:
            prod = c
            for var, i in factors:
                prod *= y[k - i] if var == "y" else uu[k - i]
            acc += prod
        y[k] = acc
    return y[lag:]


def steady_lines(coefs: dict[str, float], amp1: float, amp2: float, transient: int) -> np.ndarray:
    """Complex line coefficients X[m] of the last period: y = sum_m X[m] e^{j 2 pi m k / P}."""
    assert transient % P == 0  # the kept period starts at phase 0 of both tones
    k = np.arange(transient + P)
    u = amp1 * np.cos(2 * np.pi * M1 * k / P) + amp2 * np.cos(2 * np.pi * M2 * k / P)
    y = simulate_narx(coefs, u)[transient:]
    return np.fft.fft(y) / P


def predicted(g: Gfrf, combo: tuple[int, ...], amps: dict[int, float]) -> complex:
    """Line predicted by H_n for a combination of signed tone bins (e.g. (M1, M1, -M2))."""
    mult = Counter(combo)
    coef = math.factorial(len(combo)) / math.prod(math.factorial(v) for v in mult.values())
    scale = coef * math.prod((amps[abs(m)] / 2) for m in combo)
    return complex(scale * g.h(*[m / P for m in combo]))


COMBOS = {
    "f1+f2 (H2)": (M1, M2), "2f1 (H2)": (M1, M1), "2f2 (H2)": (M2, M2),
    "3f1 (H3)": (M1, M1, M1), "2f1-f2 (H3)": (M1, M1, -M2), "f1+2f2 (H3)": (M1, M2, M2),
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_lines_match_gfrfs(name: str) -> None:
    coefs, amp, transient = MODELS[name]
    g = Gfrf.from_model(NarxModel.from_terms(coefs))
    assert g.stable
    amps = {M1: amp, M2: 0.8 * amp}
    x = steady_lines(coefs, amps[M1], amps[M2], transient)
    for label, combo in COMBOS.items():
        want = predicted(g, combo, amps)
        got = x[sum(combo) % P]
        floor = float(np.median(np.abs(x)))  # rounding noise of the off-line bins
        assert abs(want) > 1e4 * floor, f"{name} {label}: line too weak to test"
        rel = abs(got - want) / abs(want)
        assert rel < 1e-3, f"{name} {label}: |{got:.6g}| vs |{want:.6g}|, rel {rel:.2e}"
        assert abs(abs(got) - abs(want)) / abs(want) < 1e-3


def test_h4_line_of_rich_model() -> None:
    """(A^4/8)|H4(f,f,f,f)| at 4f, one tone: the order-4 kernel of a model with cubic terms."""
    amp = 2e-3
    g = Gfrf.from_model(NarxModel.from_terms(RICH))
    x = steady_lines(RICH, amp, 0.0, P)
    want = predicted(g, (M1,) * 4, {M1: amp})
    rel = abs(x[4 * M1] - want) / abs(want)
    assert rel < 1e-3, rel


def test_contamination_is_of_higher_order() -> None:
    """Halving the amplitudes divides the line error by ~4 (order n + 2 terms), so the
    amplitudes used above are in the regime where H_n alone sets the line."""
    coefs, amp, transient = MODELS["rich"]
    g = Gfrf.from_model(NarxModel.from_terms(coefs))
    errs = []
    for a in (4 * amp, 2 * amp):
        amps = {M1: a, M2: 0.8 * a}
        x = steady_lines(coefs, a, 0.8 * a, transient)
        want = predicted(g, (M1, M2), amps)
        errs.append(abs(x[M1 + M2] - want) / abs(want))
    assert errs[1] < 1e-3 and 3.0 < errs[0] / errs[1] < 5.0, errs
