"""Benchmark: NARX structure selection against SysIdentPy's FROLS, in the same run.

One 1000-sample window of the paper's speed case (ny = 30, nu = 40, quadratic, 2556
candidates, 15 terms), single BLAS thread, median of repeated runs. Both sides get the same
1040 samples (40 lag samples + 1000 regression rows) and the same convention (raw output,
constant as an ordinary candidate: ``FitConfig(method="ofr", remove_dc=False)``), so they
must choose the same terms in the same order. Reported: both times, the ratio, the peak
extra memory (tracemalloc) of ours, the default ``iofr`` time, the live budget (speed and
position models per 250-sample hop at 500 Hz = 0.5 s), and scaling tables.

Usage: ``python bench/ofr_bench.py [--quick] [--repeats N]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
             "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from pmsm_sysid.core.selection.identify import FitConfig, fit_narx  # noqa: E402
from pmsm_sysid.core.terms.candidates import count_candidates  # noqa: E402
from pmsm_sysid.core.terms.model import Structure, Term  # noqa: E402
from pmsm_sysid.core.terms.regressors import MAX_MATRIX_BYTES  # noqa: E402

FS = 500.0
PLANT = Path(__file__).resolve().parents[1] / "plants" / "nominal_noisy.yaml"


def bench_data(n: int) -> tuple[np.ndarray, np.ndarray, str]:
    """(speed, thrust, description): the simulated motor if available, else a stand-in."""
    try:
        from pmsm_sysid.core.physics.excitation import make_excitation
        from pmsm_sysid.core.physics.motor import simulate
        from pmsm_sysid.core.physics.plant import load_plant

        plant = load_plant(PLANT)
        u = make_excitation("paper-speed", n, FS, seed=0)
        rec = simulate(plant, u, seed=0)
        return rec.speed, rec.thrust, f"simulated motor ({PLANT.name}, paper-speed 16.5 Hz)"
    except ImportError:
        rng = np.random.default_rng(0)
        pole = float(np.exp(-32.4992 / 2.3213 / FS))
        u = 50.0 * np.sin(2 * np.pi * 16.5 * np.arange(n) / FS) + rng.standard_normal(n)
        y = np.zeros(n)
        for k in range(1, n):
            y[k] = pole * y[k - 1] + (1 - pole) / 32.4992 * u[k - 1]
        return y + 0.002 * rng.standard_normal(n), u, "stand-in: first-order plant, same pole"


def median_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """Median wall time of ``repeats`` runs after a warm-up; the median thread CPU time of
    the same runs is kept in ``LAST_CPU`` (on a shared machine wall time includes waiting)."""
    global LAST_CPU
    out = fn()  # warm-up (caches, imports)
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.thread_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
    LAST_CPU = float(np.median(cpu))
    return float(np.median(times)), out


LAST_CPU = 0.0


def ours(y: np.ndarray, u: np.ndarray, st: Structure, n_terms: int, method: str = "ofr",
         remove_dc: bool = False) -> list[str]:
    cfg = FitConfig(structure=st, n_terms=n_terms, method=method, remove_dc=remove_dc)
    return fit_narx(y, u, cfg, FS).model.term_names


def peer(y: np.ndarray, u: np.ndarray, st: Structure, n_terms: int) -> list[str]:
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    m = FROLS(order_selection=False, n_terms=n_terms, ylag=st.ny, xlag=st.nu,
              estimator=LeastSquares(), basis_function=Polynomial(degree=st.degree))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m.fit(X=u[:, None], y=y[:, None])
    return [Term(tuple(("y" if c < 2000 else "u", int(c) % 1000) for c in row if c)).name
            for row in m.final_model]


def peak_memory_mb(fn: Callable[[], Any]) -> float:
    fn()
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def have_peer() -> bool:
    try:
        import sysidentpy  # noqa: F401
    except ImportError:
        return False
    return True


def headline(y: np.ndarray, u: np.ndarray, repeats: int, peer_ok: bool) -> None:
    st = Structure()
    yw, uw = y[960:2000], u[960:2000]
    t_ours, names_ours = median_time(lambda: ours(yw, uw, st, 15), repeats)
    c_ours = LAST_CPU
    print(f"window 1000 samples (rows 1000:2000), ny=30 nu=40 degree 2: "
          f"{count_candidates(st)} candidates, 15 terms; times: wall (thread CPU)")
    print(f"  ours   FROLS (ofr, SysIdentPy convention): {1e3 * t_ours:8.2f} ms "
          f"({1e3 * c_ours:.2f}) median of {repeats}")
    mem = peak_memory_mb(lambda: ours(yw, uw, st, 15))
    mem_i = peak_memory_mb(lambda: ours(yw, uw, st, 15, "iofr", True))
    print(f"  ours   peak extra memory (tracemalloc):    {mem:8.2f} MB (iOFR {mem_i:.2f} MB)")
    t_iofr, _ = median_time(lambda: ours(yw, uw, st, 15, "iofr", True), repeats)
    print(f"  ours   iOFR (default: d.c. removed):       {1e3 * t_iofr:8.2f} ms "
          f"({1e3 * LAST_CPU:.2f})")
    ypos = y[990:2000]  # position case: ny = nu = 10
    t_live, _ = median_time(lambda: (ours(yw, uw, st, 15, "iofr", True),
                                     ours(ypos, u[990:2000], Structure(ny=10, nu=10), 15,
                                          "iofr", True)), max(3, repeats // 3))
    print(f"  live   speed + position iOFR per window:   {1e3 * t_live:8.2f} ms "
          f"({1e3 * LAST_CPU:.2f}); budget 500 ms (re-fit every 250 samples at 500 Hz): "
          f"{500 / (1e3 * t_live):.0f}x margin")
    if not peer_ok:
        print("  SysIdentPy not installed (pip install -e .[bench]): no ratio")
        return
    p_rep = max(3, repeats // 6)
    t_peer, names_peer = median_time(lambda: peer(yw, uw, st, 15), p_rep)
    c_peer = LAST_CPU
    print(f"  SysIdentPy 0.9 FROLS (LeastSquares):       {1e3 * t_peer:8.2f} ms "
          f"({1e3 * c_peer:.2f}) median of {p_rep}")
    print(f"  ratio SysIdentPy / ours:                   {t_peer / t_ours:8.1f}x wall, "
          f"{c_peer / c_ours:.1f}x CPU")
    same = names_ours == names_peer
    print(f"  same terms in the same order:              {same}")
    if not same:
        print(f"    ours: {names_ours}\n    peer: {names_peer}")
    print(f"  terms: {', '.join(names_ours)}")


def scaling_length(y: np.ndarray, u: np.ndarray, repeats: int, peer_ok: bool) -> None:
    st = Structure()
    print("\ntime vs window length (ny=30, nu=40, degree 2, 15 terms; thread CPU ms, median)")
    print(f"{'rows':>6} {'ours ofr':>10} {'ours iofr':>10} {'SysIdentPy':>11} {'ratio':>7}")
    for n in (500, 1000, 2000, 4000, 8000):
        yw, uw = y[:n + 40], u[:n + 40]
        median_time(lambda yw=yw, uw=uw: ours(yw, uw, st, 15), repeats)
        c_o = LAST_CPU
        median_time(lambda yw=yw, uw=uw: ours(yw, uw, st, 15, "iofr", True),
                    max(3, repeats // 3))
        c_i = LAST_CPU
        if peer_ok:
            median_time(lambda yw=yw, uw=uw: peer(yw, uw, st, 15), 2)
            print(f"{n:>6} {1e3 * c_o:>10.2f} {1e3 * c_i:>10.2f} {1e3 * LAST_CPU:>11.1f} "
                  f"{LAST_CPU / c_o:>6.1f}x")
        else:
            print(f"{n:>6} {1e3 * c_o:>10.2f} {1e3 * c_i:>10.2f} {'-':>11} {'-':>7}")


def scaling_candidates(y: np.ndarray, u: np.ndarray, repeats: int, peer_ok: bool,
                       peer_max: int) -> None:
    print("\ntime vs candidate count (1000 rows, 15 terms; thread CPU ms, median; '-' = skipped)")
    print(f"{'deg':>3} {'ny=nu':>5} {'candidates':>10} {'engine':>8} {'ours ofr':>10} "
          f"{'SysIdentPy':>11} {'ratio':>7}")
    for degree in (2, 3):
        for lags in (10, 20, 30, 40, 50, 60):
            st = Structure(ny=lags, nu=lags, degree=degree)
            m = count_candidates(st)
            engine = "gram" if degree <= 2 else "explicit"
            yw, uw = y[:1000 + lags], u[:1000 + lags]
            if degree == 3 and 1000 * m * 8 > min(MAX_MATRIX_BYTES, 160 * 2**20):
                print(f"{degree:>3} {lags:>5} {m:>10} {engine:>8} {'-':>10} {'-':>11} {'-':>7}"
                      f"  (explicit matrix {1000 * m * 8 / 2**20:.0f} MB: skipped)")
                continue
            median_time(lambda yw=yw, uw=uw, st=st: ours(yw, uw, st, 15), max(3, repeats // 3))
            t_o = LAST_CPU
            if peer_ok and m <= peer_max:
                median_time(lambda yw=yw, uw=uw, st=st: peer(yw, uw, st, 15), 1)
                t_p = LAST_CPU
                print(f"{degree:>3} {lags:>5} {m:>10} {engine:>8} {1e3 * t_o:>10.2f} "
                      f"{1e3 * t_p:>11.1f} {t_p / t_o:>6.1f}x")
            else:
                print(f"{degree:>3} {lags:>5} {m:>10} {engine:>8} {1e3 * t_o:>10.2f} "
                      f"{'-':>11} {'-':>7}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=30, help="timed runs of ours (default 30)")
    ap.add_argument("--quick", action="store_true", help="headline only, no scaling tables")
    ap.add_argument("--peer-max", type=int, default=12000,
                    help="largest candidate set SysIdentPy is timed on (default 12000)")
    args = ap.parse_args()
    y, u, what = bench_data(9000)
    peer_ok = have_peer()
    print(f"data: {what}; single BLAS thread; numpy {np.__version__}")
    headline(y, u, args.repeats, peer_ok)
    if not args.quick:
        scaling_length(y, u, max(5, args.repeats // 3), peer_ok)
        scaling_candidates(y, u, max(5, args.repeats // 3), peer_ok, args.peer_max)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
