"""GFRF speed on the paper's 15-term thrust-speed model (Table 2, y(k-18) = -0.090082).

Target: H2 on a 256 x 256 grid in < 100 ms. There is no GFRF in the peer library
(SysIdentPy 0.9.0), so the ratios are against two baselines measured in the same run:
the same engine on the grid flattened to independent points (no broadcasting of H1 along
the axes), and a direct scalar evaluation of Eqs. 7-9 point by point (on a subsample,
scaled up), which checks the values too. The full analysis (peaks and ridges) is timed in
CPU seconds (page faults of fresh grids included) against the same analysis on a direct
array evaluation of Eqs. 7-9 (frequency sum first, a complex exponential per lag, each
ordering of Eq. 9 on its own).

    .venv/bin/python bench/gfrf_bench.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import cmath
import itertools
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from pmsm_sysid.core.frequency.analysis import analyse
from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.terms.model import NarxModel

MODEL = Path(__file__).resolve().parents[1] / "examples" / "paper_table2_speed.json"


def best_ms(fn, repeat: int, clock=time.perf_counter) -> float:  # type: ignore[no-untyped-def]
    """The best of ``repeat`` calls of ``fn`` in ms of ``clock`` (wall time by default)."""
    times = []
    for _ in range(repeat):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return 1e3 * min(times)


def scalar_h2(model: NarxModel, f1: float, f2: float) -> complex:
    """Eqs. 7-9 for n = 2 written out per point for a model with degree <= 2 terms."""
    w = (2 * math.pi * f1, 2 * math.pi * f2)

    def lin(ws: float) -> tuple[complex, complex]:
        num = den = 0j
        for t, c in zip(model.terms, model.estimates, strict=True):
            if t.degree == 1:
                lag = t.factors[0][1]
                if t.factors[0][0] == "u":
                    num += c * cmath.exp(-1j * ws * lag)
                else:
                    den += c * cmath.exp(-1j * ws * lag)
        return num, 1 - den

    def h1(x: float) -> complex:
        num, den = lin(x)
        return num / den

    total = 0j
    for a, b in ((0, 1), (1, 0)):
        wa, wb = w[a], w[b]
        num = 0j
        for t, c in zip(model.terms, model.estimates, strict=True):
            if t.degree != 2:
                continue
            (v1, l1), (v2, l2) = t.factors
            if v1 == "u" and v2 == "u":
                num += c * cmath.exp(-1j * (wa * l1 + wb * l2))
            elif v1 == "y" and v2 == "u":
                num += c * cmath.exp(-1j * wb * l2) * h1(wa) * cmath.exp(-1j * wa * l1)
            else:
                num += c * h1(wa) * cmath.exp(-1j * wa * l2) * h1(wb) * cmath.exp(-1j * wb * l1)
        total += num / lin(wa + wb)[1]
    return total / 2


def _ex(fs: Any, lag: int) -> Any:
    return np.exp(-2j * np.pi * lag * fs)


def _poly(c: Any, fs: Any) -> Any:
    return sum((c[k] * _ex(fs, k) for k in np.flatnonzero(c)), np.zeros_like(fs, complex))


def reference_h(g: Gfrf, *freqs: Any, symmetric: bool = True) -> Any:
    """Eqs. 7-9 on arrays as written: H_n^asym per ordering, the frequency sum before each
    complex exponential (shares nothing with the engine; test_gfrf_evaluation uses it too)."""
    f = [np.asarray(x, dtype=np.float64) for x in freqs]

    def asym(args: tuple[Any, ...]) -> Any:
        fs, m = sum(args), len(args)
        num: Any = _poly(g.b, fs) if m == 1 else 0.0
        for t in g.nonlinear:
            p, q = len(t.y_lags), len(t.u_lags)
            if p + q > m or (p == 0 and q != m):
                continue
            ue = math.prod((_ex(a, k) for a, k in zip(args[m - q:], t.u_lags, strict=True)),
                           start=1.0 + 0j)
            num = num + t.coef * ue * (hnp(args[:m - q], t.y_lags) if p else 1.0)
        return num / (1.0 - _poly(g.a, fs))

    def hnp(args: tuple[Any, ...], lags: tuple[int, ...]) -> Any:
        if len(lags) == 1:
            return asym(args) * _ex(sum(args), lags[0])
        return sum(asym(args[:i]) * hnp(args[i:], lags[:-1]) * _ex(sum(args[:i]), lags[-1])
                   for i in range(1, len(args) - len(lags) + 2))

    orders = list(itertools.permutations(f)) if symmetric else [tuple(f)]
    shape = np.broadcast_shapes(*(x.shape for x in f))
    return np.broadcast_to(sum(asym(p) for p in orders) / len(orders), shape)


def direct_sym(g: Gfrf, f: list[Any], labels: tuple[int, ...], symmetric: bool) -> Any:
    """:func:`reference_h` in the place of ``Gfrf._sym`` (an analysis run on it)."""
    return reference_h(g, *f, symmetric=symmetric)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--n", type=int, default=256)
    args = ap.parse_args()
    model = NarxModel.from_dict(json.loads(MODEL.read_text()))
    g = Gfrf.from_model(model)
    n = args.n
    f = np.linspace(-0.5, 0.5, n)
    grid_ms = best_ms(lambda: g.h2_grid(n), args.repeat)
    f1, f2 = (x.ravel() for x in np.meshgrid(f, f, indexing="ij"))
    flat_ms = best_ms(lambda: g.h(f1, f2), args.repeat)
    rng = np.random.default_rng(0)
    sub = rng.choice(n * n, 2000, replace=False)
    t0 = time.perf_counter()
    ref = np.array([scalar_h2(model, f1[i], f2[i]) for i in sub])
    scalar_ms = 1e3 * (time.perf_counter() - t0) * (n * n) / len(sub)
    _, h = g.h2_grid(n)
    err = float(np.max(np.abs(h.ravel()[sub] - ref) / np.maximum(np.abs(ref), 1e-300)))
    h3_ms = best_ms(lambda: g.h3_slice(n), max(1, args.repeat // 2))
    full_ms = best_ms(lambda: analyse(model), args.repeat, time.process_time)
    engine_sym = Gfrf._sym
    Gfrf._sym = direct_sym  # type: ignore[assignment,method-assign]
    try:
        direct_ms = best_ms(lambda: analyse(model), max(1, args.repeat // 2), time.process_time)
    finally:
        Gfrf._sym = engine_sym  # type: ignore[method-assign]
    print(f"model: {MODEL.name} ({len(model.terms)} terms, max lag {model.max_lag})")
    print(f"H2 {n}x{n} grid (broadcast axes)      {grid_ms:9.1f} ms   target < 100 ms: "
          f"{'PASS' if grid_ms < 100 else 'FAIL'}")
    print(f"H2 {n}x{n} as flat points             {flat_ms:9.1f} ms   x{flat_ms / grid_ms:.1f}")
    print(f"H2 {n}x{n} scalar Eqs. 7-9 (scaled)   {scalar_ms:9.1f} ms   x{scalar_ms / grid_ms:.0f}"
          f"   max rel diff {err:.1e}")
    print(f"H3 slice f1 = f3 {n}x{n}              {h3_ms:9.1f} ms")
    print(f"full analysis (peaks + H2/H3 ridges) {full_ms:9.1f} ms CPU")
    print(f"  same, Eqs. 7-9 evaluated directly  {direct_ms:9.1f} ms CPU   "
          f"x{direct_ms / full_ms:.1f}")


if __name__ == "__main__":
    main()
