"""Generalised frequency response functions of a polynomial NARX model (Eqs. 7-9 of Liu et al.
2005).

The model y(k) = sum_t theta_t prod y(k-l) prod u(k-m) is mapped to its GFRFs H_n by the
recursive probing algorithm of Peyton Jones & Billings (1989), the paper's Eqs. 7-8:

    L_n(f1..fn) H_n^asym(f1..fn) = sum c_{0,n} e^{-j2pi(f1 m1 + ... + fn mn)}
        + sum_{q=1}^{n-1} sum_{p=1}^{n-q} c_{p,q} e^{-j2pi(f_{n-q+1} m_1 + ... + f_n m_q)}
              H_{n-q,p}(f1..f_{n-q})
        + sum_{p=2}^{n} c_{p,0} H_{n,p}(f1..fn),
    L_n = 1 - sum c_{1,0}(l) e^{-j2pi(f1+...+fn) l},
    H_{n,p}(f1..fn) = sum_{i=1}^{n-p+1} H_i(f1..fi) H_{n-i,p-1}(f_{i+1}..fn)
                      e^{-j2pi(f1+...+fi) l_p},   H_{n,1} = H_n e^{-j2pi(f1+...+fn) l_1},

and symmetrised by Eq. 9, H_n^sym = (1/n!) sum over the n! permutations of H_n^asym.

Frequencies are normalised, in cycles/sample (f = f_Hz / sample rate, |f| <= 0.5).
Arguments are numpy arrays that broadcast together, so a grid costs only what its shape
needs: ``h2(f[:, None], f[None, :])`` evaluates H1 on two vectors and the denominator on the
grid. An exponential of a sum of arguments is formed as the product of per-argument powers
(a multiply, not a complex exponential, per grid point), and the n! permutations of Eq. 9
share their lower-order kernels, powers and denominator L_n.

A constant term does not enter the GFRFs: it shifts the operating point (the GFRFs describe
the response about it). Terms with y-lags or u-lags only are handled like any other term.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import GfrfError
from ..terms.model import NarxModel

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
MAX_ORDER = 4
_TWO_PI_J = 2j * np.pi
_Key = tuple[int, ...]


@dataclass(frozen=True)
class _NlTerm:
    coef: float
    y_lags: tuple[int, ...]
    u_lags: tuple[int, ...]


def to_hz(f_norm: ArrayLike, sample_rate_hz: float) -> FloatArray:
    """Normalised frequency (cycles/sample) to Hz."""
    return np.asarray(f_norm, dtype=np.float64) * float(sample_rate_hz)


def to_norm(f_hz: ArrayLike, sample_rate_hz: float) -> FloatArray:
    """Hz to normalised frequency (cycles/sample)."""
    return np.asarray(f_hz, dtype=np.float64) / float(sample_rate_hz)


def check_frequencies(freqs: Sequence[ArrayLike]) -> list[FloatArray]:
    """Validate normalised frequencies: finite, |f| <= 0.5, broadcastable; GfrfError if not."""
    out = [np.asarray(f, dtype=np.float64) for f in freqs]
    for f in out:
        if not np.all(np.isfinite(f)):
            raise GfrfError("frequencies must be finite (got NaN/Inf)")
        if f.size and float(np.max(np.abs(f))) > 0.5 + 1e-12:
            raise GfrfError(
                f"normalised frequency {float(np.max(np.abs(f))):g} outside [-0.5, 0.5] "
                "(cycles/sample)")
    try:
        np.broadcast_shapes(*(f.shape for f in out))
    except ValueError as exc:
        raise GfrfError(f"frequency arrays do not broadcast: {exc}") from exc
    return out


@dataclass(frozen=True)
class Gfrf:
    """The GFRFs H_1..H_4 of one NARX model; build with :meth:`from_model`."""

    a: FloatArray                  # linear AR part: a[l] is the coefficient of y(k-l)
    b: FloatArray                  # linear input part: b[m] is the coefficient of u(k-m)
    nonlinear: tuple[_NlTerm, ...]
    sample_rate_hz: float = 1.0

    @classmethod
    def from_model(cls, model: NarxModel) -> Gfrf:
        """Split a model into its linear AR and input polynomials and nonlinear terms."""
        if not np.all(np.isfinite(model.estimates)):
            raise GfrfError("model has non-finite estimates")
        ymax = max((max(t.y_lags) for t in model.terms if t.y_lags), default=0)
        umax = max((max(t.u_lags) for t in model.terms if t.u_lags), default=0)
        if max(ymax, umax) > MAX_LAG:
            raise GfrfError(f"largest lag {max(ymax, umax)} exceeds {MAX_LAG}: the poles and "
                            "GFRFs of such a model are not computed")
        a = np.zeros(ymax + 1)
        b = np.zeros(umax + 1)
        nl: list[_NlTerm] = []
        for term, c in zip(model.terms, model.estimates, strict=True):
            ylags, ulags = term.y_lags, term.u_lags
            if term.is_constant:
                continue
            if term.degree == 1 and ylags:
                a[ylags[0]] += float(c)
            elif term.degree == 1:
                b[ulags[0]] += float(c)
            else:
                nl.append(_NlTerm(float(c), ylags, ulags))
        return cls(a=a, b=b, nonlinear=tuple(nl), sample_rate_hz=float(model.sample_rate_hz))

    @property
    def is_linear(self) -> bool:
        return not self.nonlinear

    def poles(self) -> ComplexArray:
        """Poles of the linear part: roots of z^K - a1 z^(K-1) - ... - aK (largest first)."""
        coeffs = np.concatenate(([1.0], -self.a[1:]))
        coeffs = np.trim_zeros(coeffs, trim="b")
        roots = np.roots(coeffs).astype(np.complex128) if len(coeffs) > 1 else np.zeros(0, complex)
        return roots[np.argsort(-np.abs(roots), kind="stable")]

    @property
    def stable(self) -> bool:
        p = self.poles()
        return bool(np.all(np.abs(p) < 1.0))

    def h(self, *freqs: ArrayLike, symmetric: bool = True) -> ComplexArray:
        """H_n at normalised frequencies (n = number of arguments, 1..4), broadcast together."""
        n = len(freqs)
        if not 1 <= n <= MAX_ORDER:
            raise GfrfError(f"GFRF order must be 1..{MAX_ORDER} (got {n} frequencies)")
        f = check_frequencies(freqs)
        return self._h(f, symmetric)

    def h_wrapped(self, *freqs: ArrayLike, symmetric: bool = True) -> ComplexArray:
        """As :meth:`h`, for any finite frequencies (the GFRFs are 1-periodic in each one)."""
        f = [np.asarray(x, dtype=np.float64) for x in freqs]
        if not all(np.all(np.isfinite(x)) for x in f):
            raise GfrfError("frequencies must be finite (got NaN/Inf)")
        return self._h(f, symmetric)

    def _h(self, f: list[FloatArray], symmetric: bool) -> ComplexArray:
        # Arguments passed as the same array object share one label, so their permutations
        # are evaluated once (e.g. H3(f, t, f) needs 3 of the 6 orderings of Eq. 9).
        labels = tuple(next(j for j in range(i + 1) if f[j] is f[i]) for i in range(len(f)))
        # A pole on the unit circle gives inf (nan where inf meets 0) at its frequency.
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return self._sym(f, labels, symmetric)

    def _sym(self, f: list[FloatArray], labels: tuple[int, ...], symmetric: bool) -> ComplexArray:
        ev = _Evaluator(self, f)
        shape = np.broadcast_shapes(*(x.shape for x in f))
        if not symmetric or len(f) == 1:
            return np.broadcast_to(ev.asym(labels), shape).astype(np.complex128)
        # Every ordering shares L_n (Eq. 7): sum the numerators, divide once.
        total = np.zeros(shape, dtype=np.complex128)
        for perm, count in Counter(itertools.permutations(labels)).items():
            total += count * ev.num(perm)
        return np.asarray(total / (ev.den(labels) * math.factorial(len(f))),
                          dtype=np.complex128)

    def h1(self, f: ArrayLike) -> ComplexArray:
        return self.h(f)

    def h2(self, f1: ArrayLike, f2: ArrayLike) -> ComplexArray:
        return self.h(f1, f2)

    def h3(self, f1: ArrayLike, f2: ArrayLike, f3: ArrayLike) -> ComplexArray:
        return self.h(f1, f2, f3)

    def h1_curve(self, n: int = 1025) -> tuple[FloatArray, ComplexArray]:
        """H1 on n points over [0, 0.5] cycles/sample."""
        f = np.linspace(0.0, 0.5, _check_grid(n, MAX_CURVE))
        return f, self.h(f)

    def h2_grid(self, n: int = 256, fmax: float = 0.5) -> tuple[FloatArray, ComplexArray]:
        """H2^sym on an n x n grid over [-fmax, fmax]^2: H[i, j] = H2(f[i], f[j])."""
        f = np.linspace(-fmax, fmax, _check_grid(n))
        return f, self.h(f[:, None], f[None, :])

    def h3_slice(self, n: int = 128, fmax: float = 0.5) -> tuple[FloatArray, ComplexArray]:
        """H3^sym on the slice f1 = f3 (Fig. 14 of Liu et al. 2005): H[i, j] = H3(f[i], f[j],
        f[i])."""
        f = np.linspace(-fmax, fmax, _check_grid(n))
        return f, self.h(f[:, None], f[None, :], f[:, None])


MAX_GRID = 2048      # per axis of a 2-D grid (4.2 M points)
MAX_LAG = 1024       # largest lag of a model (its poles: eigenvalues of a MAX_LAG^2 matrix)
MAX_CURVE = 1 << 20  # points of a 1-D curve


def _check_grid(n: int, limit: int = MAX_GRID) -> int:
    if not 2 <= int(n) <= limit:
        raise GfrfError(f"grid size must be 2..{limit} points per axis (got {n})")
    return int(n)


class _Evaluator:
    """One evaluation of Eqs. 7-8 on fixed argument arrays.

    The exponential of a sum of arguments is the product of per-argument powers,
    e^{-j2pi(f_a+f_b)l} = z_a^l z_b^l with z_i = e^{-j2pi f_i}: on a grid spanned by a column and
    a row that is one multiply per point instead of a complex exponential. Kept for the whole
    evaluation: the powers, the lower-order kernels H_m^asym and the denominators L_m (shared
    by all orderings of the same arguments). Products over several arguments and H_{n,p} are
    formed again where used, as a fresh grid-sized array costs more than the multiply.
    """

    def __init__(self, g: Gfrf, f: list[FloatArray]) -> None:
        self.g = g
        self.f = f
        self._pow: dict[tuple[int, int], ComplexArray] = {}
        self._asym: dict[_Key, ComplexArray] = {}
        self._den: dict[_Key, ComplexArray] = {}
        self._groups: dict[_Key, list[tuple[int, int]]] = {}

    def power(self, i: int, lag: int) -> ComplexArray:
        """z_i^lag = e^{-j 2 pi f_i lag} from z_i by halving the lag (z^l = z^h z^(l-h),
        h = l // 2), cached. Its rounding error grows in proportion to the lag, as that of
        e^{-j 2 pi f l} evaluated directly does (through the rounding of f l)."""
        key = (i, lag)
        if key not in self._pow:
            if lag <= 1:
                self._pow[key] = np.exp(-_TWO_PI_J * lag * self.f[i])
            else:
                half = lag // 2
                self._pow[key] = self.power(i, half) * self.power(i, lag - half)
        return self._pow[key]

    def exp(self, idx: _Key, lag: int, coef: float = 1.0) -> ComplexArray:
        """coef e^{-j 2 pi (sum of the indexed frequencies) lag}: the product of the arguments'
        powers (a repeated argument as one power), smallest first."""
        key = tuple(sorted(idx))
        if key not in self._groups:
            count = Counter(key)
            self._groups[key] = sorted(count.items(), key=lambda ik: self.f[ik[0]].size)
        return _prod([coef, *(self.power(i, k * lag) for i, k in self._groups[key])])

    def shape(self, idx: _Key) -> tuple[int, ...]:
        return np.broadcast_shapes(*(self.f[i].shape for i in idx))

    def _poly(self, c: FloatArray, idx: _Key) -> ComplexArray:
        """sum_l c[l] e^{-j 2 pi f l} at f = sum of the indexed frequencies: term by term over
        the nonzero c[l] when they are sparse, else by Horner in z = e^{-j 2 pi f}."""
        acc = np.zeros(self.shape(idx), dtype=np.complex128)
        nz = np.flatnonzero(c)
        if len(nz) * 3 < len(c):
            for k in nz:
                acc += self.exp(idx, int(k), float(c[k]))
            return acc
        z = self.exp(idx, 1)
        acc += c[-1]
        for coef in c[-2::-1]:
            acc *= z
            acc += coef
        return acc

    def den(self, idx: _Key) -> ComplexArray:
        """L_m of Eq. 7 at the sum of the indexed frequencies (the same for every ordering)."""
        key = tuple(sorted(idx))
        if key not in self._den:
            self._den[key] = 1.0 - self._poly(self.g.a, key)
        return self._den[key]

    def asym(self, idx: _Key) -> ComplexArray:
        """H_m^asym over the arguments idx (Eq. 7), m = len(idx), cached."""
        if idx not in self._asym:
            self._asym[idx] = np.asarray(self.num(idx) / self.den(idx), dtype=np.complex128)
        return self._asym[idx]

    def num(self, idx: _Key) -> Any:
        """The right-hand side of Eq. 7 over the arguments idx (0.0 when no term enters)."""
        m = len(idx)
        num: Any = self._poly(self.g.b, idx) if m == 1 else 0.0
        for t in self.g.nonlinear:
            p, q = len(t.y_lags), len(t.u_lags)
            if p + q > m or (p == 0 and q != m):
                continue
            if p == 0:  # c_{0,n}: pure input term
                num = num + self._inputs(idx, t.u_lags, t.coef)
            elif q == 0:  # c_{p,0}, p >= 2
                num = num + t.coef * self.hnp(idx, t.y_lags)
            else:  # c_{p,q} cross term: inputs take the last q arguments
                ue = self._inputs(idx[m - q:], t.u_lags, t.coef)
                num = num + ue * self.hnp(idx[:m - q], t.y_lags)
        return num

    def _inputs(self, idx: _Key, u_lags: tuple[int, ...], coef: float) -> ComplexArray:
        """coef e^{-j 2 pi (f_1 m_1 + ... + f_q m_q)} over the arguments idx, smallest first."""
        factors = sorted((self.power(i, lag) for i, lag in zip(idx, u_lags, strict=True)),
                         key=np.size)
        return _prod([coef, *factors])

    def hnp(self, idx: _Key, y_lags: tuple[int, ...]) -> ComplexArray:
        """H_{n,p} of Eq. 8 over the arguments idx for output lags (l_1..l_p)."""
        n, p = len(idx), len(y_lags)
        if p == 1:
            return self.asym(idx) * self.exp(idx, y_lags[0])
        return np.asarray(sum(
            self.asym(idx[:i]) * self.exp(idx[:i], y_lags[-1])
            * self.hnp(idx[i:], y_lags[:-1]) for i in range(1, n - p + 2)),
            dtype=np.complex128)


def _prod(items: Any) -> ComplexArray:
    acc: Any = 1.0
    for x in items:
        acc = acc * x
    return np.asarray(acc, dtype=np.complex128)
