"""Locate over frequency with GFRFs: which ridges exist in the real data's model only?

The same modest NARX structure (``ny = nu = 10``, degree 2, delay 1; terms by OFR (Eq. 4
of Liu et al. 2005) with the model size by BIC, at most 20) is fitted, speed from thrust, to the
central
``MAX_SAMPLES`` of the estimation data and to a **noisy simulated twin**: the plant (its noise
blocks off) driven by the recorded thrust from the measured state at the start of the
window, plus white speed noise scaled so that the twin's one-step-ahead residual matches
the real model's (one refit if the first draw is off by more than 10 %). A noise-free twin
would give a model whose GFRF ridges are numerical dust (−350 dB); with matched noise the
twin shows what the plant and the noise alone put into such a model.

Each model's GFRFs (Eqs. 7-9 of Liu et al. 2005) are analysed by
:func:`~pmsm_sysid.core.frequency.analysis.analyse` (H1 peaks, H2 ridges, each judged
``supported`` by the estimation input or not). An H1 peak counts when it is supported and the
measured speed stands ``SNR_MIN_DB`` above the model's one-step residual at its frequency (where
the speed is all noise, as at high frequencies under a position loop, a noise-fitted linear part
has peaks anywhere). An H2
ridge counts when it is supported and the model's nonlinear terms are **significant**: a
prewhitened nested F-test of the nonlinear terms against the model's linear terms,
Bonferroni-corrected for every subset of that many nonlinear candidates and every model
size (−log10 p ≥ −log10 α). ``analyse``'s ``weak`` flag (nonlinear ERR below 0.1 % of the
output variance) is reported but not used as the gate: the speed of this motor is so well
predicted linearly that a nonlinearity far above the residual noise is still "weak" by that
measure (thrust u + 0.01 u², 1.3 N rms of distortion on a 9 N rms multisine: ERR 2e-4,
yet −log10 p > 100 in the F-test); the F-test and the twin judge it against the noise
instead. A real ridge is *only in real* when no counted twin ridge of the same family
(``f1``/``f2``, one family by symmetry, or ``f1+f2``) lies within ``tolerance_hz`` =
max(``TOL_NORM`` · fs, two frequency bins of the window); a real peak when the twin's model
has no H1 peak at all within it (a twin peak, counted or not, is the plant's own).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch
from scipy.special import gammaln

from ..errors import PmsmSysidError
from ..frequency.analysis import GfrfAnalysis, analyse, nonlinear_err
from ..physics.motor import MotorSimulator, simulate
from ..physics.plant import Plant
from ..plantfit.stats import nested_f_test
from ..recording.signals import Recording
from ..selection.identifiability import ExcitationSummary, excitation_summary
from ..selection.identify import FitConfig, NarxFit, fit_narx
from ..terms.candidates import candidate_set
from ..terms.model import NarxModel, Structure
from ..terms.regressors import lag_base, target, term_matrix

FloatArray = NDArray[np.float64]

STRUCTURE = Structure(ny=10, nu=10, degree=2, delay=1)
MAX_TERMS = 20
MAX_SAMPLES = 1500
TOL_NORM = 0.005
NOISE_SEED = 0
SNR_MIN_DB = 10.0


@dataclass(frozen=True)
class ModelSide:
    """One side of the comparison: the fitted model, its analysis and its significance."""

    fit: NarxFit
    analysis: dict[str, Any]
    significance: float      # -log10 of the corrected p-value of the nonlinear terms
    significant: bool
    snr: tuple[FloatArray, FloatArray]  # (Hz, dB): output PSD over the residual's

    def snr_db(self, freq_hz: float) -> float:
        """Output-to-residual power ratio at ``freq_hz`` (dB; the lowest bin for DC)."""
        f, db = self.snr
        return float(np.interp(max(abs(freq_hz), float(f[1])), f, db))

    def summary(self) -> dict[str, Any]:
        m = self.fit.model
        return {"terms": len(m.terms),
                "nonlinear_terms": [t.name for t in m.terms if t.degree > 1],
                "nonlinear_err": nonlinear_err(m), "significance": self.significance,
                "significant": self.significant,
                "weak": bool(self.analysis["h2"].get("weak", True)),
                "residual_std": float(np.std(self.fit.residuals)),
                "h1_peaks": len(self.analysis["h1"]["peaks"]),
                "h2_ridges": len(_positive(self.analysis["h2"].get("ridges", [])))}


def _positive(ridges: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One of each ±f0 twin pair (H(-f) = conj H(f) lists both)."""
    return [r for r in ridges if r.get("sign", 1) > 0 or r["freq_norm"] == 0.0]


def nonlinear_significance(model: NarxModel, y: FloatArray, u: FloatArray) -> float:
    """-log10 of the Bonferroni-corrected p-value that the model's nonlinear terms matter.

    Nested F-test (prewhitened, :func:`.stats.nested_f_test`) of the nonlinear columns
    against the linear ones on the fitting data; the correction multiplies by the number of
    ways to choose that many nonlinear candidates and by the number of model sizes tried.
    """
    nl = [t for t in model.terms if t.degree > 1]
    if not nl:
        return 0.0
    st = model.structure or STRUCTURE
    cset = candidate_set(st)
    base = lag_base(y, u, st)
    lin_idx = np.array([cset.position(t) for t in model.terms if t.degree <= 1], dtype=np.intp)
    nl_idx = np.array([cset.position(t) for t in nl], dtype=np.intp)
    test = nested_f_test(target(y, st), term_matrix(base, cset, lin_idx),
                         term_matrix(base, cset, nl_idx))
    n_nl = sum(1 for t in cset.terms if t.degree > 1)
    q = len(nl)
    log10_subsets = float(gammaln(n_nl + 1) - gammaln(q + 1) - gammaln(n_nl - q + 1)) \
        / math.log(10.0)
    corrected = test.log10_p + log10_subsets + math.log10(MAX_TERMS)
    return float(max(0.0, -corrected))


def _side(y: FloatArray, u: FloatArray, fs: float, ex: ExcitationSummary,
          alpha: float) -> ModelSide:
    cfg = FitConfig(structure=STRUCTURE, n_terms=MAX_TERMS, criterion="bic", method="ofr")
    fit = fit_narx(y, u, cfg, fs)
    ana: GfrfAnalysis = analyse(fit.model, ex, orders=(1, 2))
    sig = nonlinear_significance(fit.model, y, u)
    return ModelSide(fit, ana.to_dict(), sig, sig >= -math.log10(alpha),
                     _snr(y[STRUCTURE.max_lag:], fit.residuals, fs))


def _snr(y: FloatArray, e: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
    """Welch PSD of the output over that of the one-step residual, in dB."""
    n = min(len(y), len(e), 256)
    f, py = welch(y[-len(e):], fs=fs, nperseg=n)
    _, pe = welch(e, fs=fs, nperseg=n)
    return f, 10.0 * np.log10(np.maximum(py, 1e-300) / np.maximum(pe, 1e-300))


def _window(n: int, lag: int) -> tuple[int, int]:
    """The central MAX_SAMPLES of n samples, with ``lag`` samples of history before."""
    size = min(n - lag, MAX_SAMPLES)
    start = lag + (n - lag - size) // 2
    return start - lag, start + size


def _twin(plant: Plant, rec: Recording, a: int, b: int) -> FloatArray:
    """The noise-free plant's speed under the window's thrust, from the measured state.

    ``MotorSimulator.replay`` without restarts is ``simulate``'s speed for a plant without
    noise and quantisation (the same states; with Rk4's linear path 9.5 ms -> 5.0 ms of CPU on
    ``bags/real_axis``);
    ``simulate`` itself where the thrust or the speed is not finite (its errors, its values).
    """
    clean = replace(plant, noise=None, quantisation=None, sample_rate_hz=rec.sample_rate_hz)
    u, x0, v0 = rec.thrust[a:b], float(rec.position[a]), float(rec.speed[a])
    if len(u) and np.isfinite(u).all() and math.isfinite(x0) and math.isfinite(v0):
        speed, _ = MotorSimulator(clean, seed=0, x0=x0, v0=v0).replay(u.tolist(), [], [], [])
        if len(speed) == len(u):
            return np.array(speed, dtype=np.float64)
    sim = simulate(clean, u, x0=x0, v0=v0)
    return np.asarray(sim.speed, dtype=np.float64)


def counted(side: ModelSide) -> tuple[list[dict[str, Any]], list[dict[str, Any]], int, int]:
    """(peaks, ridges) that count, and how many of each were left out as unsupported (by the
    input's spectrum, or for a peak by an output that does not stand SNR_MIN_DB above
    the residual there: H1 is not determined where the speed is all noise)."""
    peaks = side.analysis["h1"]["peaks"]
    ridges = _positive(side.analysis["h2"].get("ridges", [])) if side.significant else []
    keep_p = [p for p in peaks if p.get("supported") is not False
              and side.snr_db(p["freq_hz"]) >= SNR_MIN_DB]
    keep_r = [r for r in ridges if r.get("supported") is not False]
    return keep_p, keep_r, len(peaks) - len(keep_p), len(ridges) - len(keep_r)


def _family(kind: str) -> str:
    return "f1" if kind in ("f1", "f2") else kind


def only_in_first(first: list[dict[str, Any]], second: list[dict[str, Any]],
                  tol_hz: float, ridge: bool) -> list[dict[str, Any]]:
    """Features of ``first`` with no feature of ``second`` (same family) within tol_hz."""
    out, seen = [], set()
    for f in first:
        fam = _family(f["kind"]) if ridge else "h1"
        match = any(abs(abs(f["freq_hz"]) - abs(g["freq_hz"])) <= tol_hz
                    and (not ridge or _family(g["kind"]) == fam) for g in second)
        key = (fam, round(abs(f["freq_hz"]) / max(tol_hz, 1e-12)))
        if not match and key not in seen:
            seen.add(key)
            row = {"kind": f["kind"], "freq_hz": abs(float(f["freq_hz"])),
                   "gain_db": f.get("gain_db")}
            if ridge:
                row |= {"order": 2, "prominence_db": f.get("prominence_db"),
                        "dominant": f.get("dominant")}
            out.append(row)
    return out


def gfrf_where(plant: Plant, rec: Recording, alpha: float = 1e-3) -> dict[str, Any]:
    """The ``mismatch.where`` entry of the GFRF comparison (module doc); on data a NARX
    cannot be fitted to, an entry that says why instead."""
    t0 = time.perf_counter()
    head: dict[str, Any] = {"axis": "frequency", "source": "gfrf"}
    try:
        return head | _compare(plant, rec, alpha) | {
            "timing_ms": 1e3 * (time.perf_counter() - t0)}
    except (PmsmSysidError, ValueError, np.linalg.LinAlgError) as exc:
        return head | {"skipped": True, "ridges_only_in_real": [], "peaks_only_in_real": [],
                       "note": f"GFRF comparison not possible on these data: {exc}"}


def _compare(plant: Plant, rec: Recording, alpha: float) -> dict[str, Any]:
    fs = rec.sample_rate_hz
    a, b = _window(len(rec), STRUCTURE.max_lag)
    u, y = rec.thrust[a:b], rec.speed[a:b]
    ex = excitation_summary(u[STRUCTURE.max_lag:], fs)
    real = _side(y, u, fs, ex, alpha)
    clean = _twin(plant, rec, a, b)
    rng = np.random.default_rng(NOISE_SEED)
    z = rng.standard_normal(len(clean))
    target_std = float(np.std(real.fit.residuals))
    sigma = target_std
    twin = _side(clean + sigma * z, u, fs, ex, alpha)
    got = float(np.std(twin.fit.residuals))
    if got > 0 and abs(got / target_std - 1.0) > 0.1:
        sigma *= target_std / got
        twin = _side(clean + sigma * z, u, fs, ex, alpha)
    tol = max(TOL_NORM * fs, 2.0 * fs / (b - a))
    rp, rr, p_drop, r_drop = counted(real)
    _, tr, _, _ = counted(twin)
    ridges = only_in_first(rr, tr, tol, ridge=True)
    # any twin peak nearby, counted or not, is the plant's own: not a discrepancy
    peaks = only_in_first(rp, twin.analysis["h1"]["peaks"], tol, ridge=False)
    return {"ridges_only_in_real": ridges, "peaks_only_in_real": peaks,
            "tolerance_hz": tol, "window": [a, b], "samples": b - a,
            "structure": {"ny": STRUCTURE.ny, "nu": STRUCTURE.nu, "degree": STRUCTURE.degree,
                          "delay": STRUCTURE.delay, "criterion": "bic",
                          "max_terms": MAX_TERMS},
            "significance": real.significance,
            "real": real.summary() | {"peaks_left_out": p_drop, "ridges_left_out": r_drop},
            "twin": twin.summary() | {"noise_std": sigma},
            "excitation": ex.describe(),
            "note": _note(real, twin, ridges, peaks, r_drop)}


def _note(real: ModelSide, twin: ModelSide, ridges: list[dict[str, Any]],
          peaks: list[dict[str, Any]], ridges_left_out: int) -> str:
    def where(rows: list[dict[str, Any]]) -> str:
        return ", ".join(f"{r['kind']} at {r['freq_hz']:.1f} Hz" for r in rows)

    if ridges:
        text = "H2 ridges only in the real data's model: " + where(ridges)
    elif not real.significant and not twin.significant:
        text = ("neither the real data's NARX nor its noisy twin's has significant nonlinear "
                "terms: no H2 ridges to compare")
    elif real.significant and not twin.significant:
        text = ("the real data's NARX has significant nonlinear terms the twin's lacks "
                f"(-log10 p = {real.significance:.1f}) but no distinct supported H2 ridge")
    elif real.significant:
        text = ("both models have significant nonlinear terms and every supported H2 ridge "
                "of the real one is matched in the twin's: the plant carries this "
                "nonlinearity already")
    else:
        text = ("only the twin's NARX has significant nonlinear terms: the plant's "
                "nonlinearity is not seen in the real data")
    if ridges_left_out:
        text += (f" ({ridges_left_out} ridge(s) of the real data's model left out: not "
                 "supported by the excitation)")
    if peaks:
        text += "; H1 peaks only in the real data's model: " + where(peaks)
    return text
