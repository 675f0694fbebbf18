"""NARX identification end to end: data checks, OFR/iOFR selection, least squares,
validation. Used offline by ``pmsm-sysid identify`` and online by the identifier node.

:func:`fit_narx` fits arrays; row k of the regression is every sample k >= L = max lag of the
structure, so callers that want a window's every sample as a regression row pass the L
samples before it too (:func:`identify_recording` does this when the recording has them).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, IdentificationError
from ..terms.candidates import candidate_set
from ..terms.model import NarxModel, Structure
from ..terms.regressors import Projector, lag_base, make_projector, target
from ..validation.correlation import CorrelationTests, FitMetrics, correlation_tests, fit_metrics
from ..validation.prediction import one_step_ahead, simulate
from .datacheck import DataCheck, check_sampling, describe_fit_data, validate_fit_data
from .iofr import iofr
from .ofr import CRITERIA, OfrResult, frols, information_criterion, least_squares

FloatArray = NDArray[np.float64]
METHODS = ("iofr", "ofr")


@dataclass(frozen=True)
class FitConfig:
    """How to identify: candidate structure, model size rule, selection method.

    ``criterion``: ``terms`` (exactly ``n_terms``), ``err`` (stop once 1 - sum ERR < rho, at
    most ``n_terms``), ``aic``/``bic`` (size minimising the criterion, at most ``n_terms``).
    ``method``: ``iofr`` (FROLS + exact term exchange, :mod:`.iofr`; default) or ``ofr`` (the
    paper's classic FROLS, :mod:`.ofr`). ``remove_dc``: the paper's d.c. removal in Eq. 4 (the
    constant is then always in the model); needs ``structure.constant``.
    """

    structure: Structure = field(default_factory=Structure)
    n_terms: int = 15
    criterion: str = "terms"
    rho: float = 1e-3
    method: str = "iofr"
    remove_dc: bool = True
    engine: str = "auto"

    def __post_init__(self) -> None:
        if self.criterion not in CRITERIA:
            raise IdentificationError(
                f"unknown criterion '{self.criterion}' ({', '.join(CRITERIA)})")
        if self.method not in METHODS:
            raise IdentificationError(f"unknown method '{self.method}' ({', '.join(METHODS)})")
        if self.n_terms < 1:
            raise IdentificationError(f"need at least one term (got {self.n_terms})")
        if not (np.isfinite(self.rho) and 0 < self.rho < 1):
            raise IdentificationError(f"rho must be in (0, 1) (got {self.rho})")

    @property
    def dc_removed(self) -> bool:
        return self.remove_dc and self.structure.constant


@dataclass(frozen=True)
class NarxFit:
    """An identified model with how it was found."""

    model: NarxModel
    n_candidates: int
    timing_ms: dict[str, float]
    criterion_values: FloatArray  # per model size along the greedy path (see fit_narx)
    sum_err: float
    method: str = "iofr"
    criterion: str = "terms"
    greedy_terms: tuple[str, ...] = ()  # the plain FROLS choice before refinement
    n_swaps: int = 0
    dc_removed: bool = True
    data_check: DataCheck | None = None
    residuals: FloatArray = field(default_factory=lambda: np.zeros(0))


def _criterion_path(res: OfrResult, n_obs: int, criterion: str) -> FloatArray:
    if criterion in ("aic", "bic"):
        return information_criterion(res.sse, n_obs, res.sizes, criterion)
    return 1.0 - res.sse / res.sst  # cumulative ERR = explained fraction


def _select(
    proj: Projector, t: FloatArray, config: FitConfig, const: int | None
) -> tuple[OfrResult, OfrResult, int]:
    """(final selection, greedy FROLS selection, number of exchanges)."""
    dc = config.dc_removed
    if config.method == "iofr":
        r = iofr(proj, t, config.n_terms, remove_dc=dc, constant_index=const,
                 criterion=config.criterion, rho=config.rho)
        return r.ofr, r.greedy, r.n_swaps
    rho = config.rho if config.criterion == "err" else None
    res = frols(proj, t, config.n_terms, remove_dc=dc, constant_index=const, rho=rho)
    greedy = res
    if config.criterion in ("aic", "bic"):
        best = int(np.argmin(information_criterion(res.sse, len(t), res.sizes, config.criterion)))
        keep = int(res.sizes[best])
        res = OfrResult(selected=res.selected[:keep], err=res.err[:keep], sse=res.sse[: best + 1],
                        sst=res.sst, remove_dc=dc, n_forced=res.n_forced, n_skipped=res.n_skipped)
    return res, greedy, 0


def _shortfall(check: DataCheck, config: FitConfig, got: int, candidates: int) -> DataCheck:
    """Add a warning when fewer terms than ``--terms`` were selectable (criterion terms)."""
    if config.criterion != "terms" or got >= config.n_terms:
        return check
    why = (f"there are only {candidates} candidates" if candidates < config.n_terms else
           "the remaining candidates are linearly dependent on the chosen ones on these data "
           "(rank-deficient candidate set, e.g. u^2 = 1 for a two-level input)")
    note = f"{got} terms instead of the {config.n_terms} asked for: {why}"
    return replace(check, warnings=(*check.warnings, note))


def fit_narx(
    y: FloatArray,
    u: FloatArray,
    config: FitConfig,
    sample_rate_hz: float = 1.0,
    input_name: str = "thrust",
    output_name: str = "speed",
) -> NarxFit:
    """Identify a polynomial NARX model of y from u (rows k = L..N-1).

    Raises DataError / InsufficientExcitationError on unusable data (see
    :func:`.datacheck.check_fit_data`) and IdentificationError if no model can be formed.
    ``criterion_values`` holds, per model size along the greedy path, the cumulative ERR
    (``terms``/``err``) or the AIC/BIC values.
    """
    t0 = time.perf_counter()
    st = config.structure
    n_params = config.n_terms + (1 if config.dc_removed else 0)
    validate_fit_data(y, u, st, n_params, input_name, output_name)
    y = np.asarray(y, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    cset = candidate_set(st)
    base = lag_base(y, u, st)
    check = describe_fit_data(u, st, input_name, base[:, 1 + st.ny :], y=y,
                              output_name=output_name)
    t = target(y, st)
    proj = make_projector(base, cset, config.engine)
    t1 = time.perf_counter()
    res, greedy, n_swaps = _select(proj, t, config, cset.constant_index)
    t2 = time.perf_counter()
    ls = least_squares(proj.columns(res.selected), t)
    t3 = time.perf_counter()
    check = _shortfall(check, config, len(res.selected) - int(config.dc_removed),
                       cset.n_candidates - int(config.dc_removed))
    model = NarxModel(
        terms=tuple(cset.terms[i] for i in res.selected.tolist()), estimates=ls.theta,
        std=ls.std, err=res.err, sample_rate_hz=float(sample_rate_hz),
        input_name=input_name, output_name=output_name, structure=st,
    )
    timing = {"regressors": 1e3 * (t1 - t0), "selection": 1e3 * (t2 - t1),
              "estimation": 1e3 * (t3 - t2), "total": 1e3 * (t3 - t0)}
    return NarxFit(
        model=model, n_candidates=cset.n_candidates, timing_ms=timing,
        criterion_values=_criterion_path(greedy, len(t), config.criterion),
        sum_err=float(np.sum(res.err)), method=config.method, criterion=config.criterion,
        greedy_terms=tuple(cset.term_names[i] for i in greedy.selected.tolist()),
        n_swaps=n_swaps, dc_removed=config.dc_removed, data_check=check,
        residuals=ls.residuals,
    )


@dataclass(frozen=True)
class ValidationReport:
    """Section II.3 of Liu et al. (2005): model predicted output (Eq. 12) on the estimation and an
    independent validation window, one-step-ahead R^2, and the correlation tests (Eq. 13) on the
    one-step-ahead residuals of the estimation window."""

    estimation: FitMetrics
    validation: FitMetrics | None
    osa_r2: float
    correlation: CorrelationTests
    free_run_diverged: bool
    validation_osa_r2: float | None = None
    estimation_diverged: bool = False
    validation_diverged: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The identify JSON's "validation" object."""
        est = {**self.estimation.to_dict(), "osa_r2": self.osa_r2,
               "free_run_diverged": self.estimation_diverged}
        val = None
        if self.validation is not None:
            val = {**self.validation.to_dict(), "osa_r2": self.validation_osa_r2,
                   "free_run_diverged": self.validation_diverged}
        return {"estimation": est, "validation": val,
                "correlation_tests": self.correlation.to_dict(),
                "correlation_all_pass": self.correlation.all_pass,
                "free_run_diverged": self.free_run_diverged}


def _window_fit(model: NarxModel, y: FloatArray, u: FloatArray) -> tuple[FitMetrics, float, bool]:
    lag = model.max_lag
    run = simulate(model, u, y[:lag])
    osa = one_step_ahead(model, y, u)
    return fit_metrics(y[lag:], run.y[lag:]), fit_metrics(y[lag:], osa[lag:]).r2, run.diverged


def validate_narx(
    model: NarxModel,
    y_est: FloatArray,
    u_est: FloatArray,
    y_val: FloatArray | None = None,
    u_val: FloatArray | None = None,
    max_lag: int = 20,
) -> ValidationReport:
    """Validate on samples k >= L of each window (the first L outputs start the free run)."""
    y_est = np.asarray(y_est, dtype=np.float64)
    u_est = np.asarray(u_est, dtype=np.float64)
    lag = model.max_lag
    est, osa_r2, div_e = _window_fit(model, y_est, u_est)
    resid = (y_est - one_step_ahead(model, y_est, u_est))[lag:]
    corr = correlation_tests(resid, u_est[lag:], max_lag=max_lag)
    val, val_osa, div_v = None, None, False
    if y_val is not None and u_val is not None:
        val, val_osa, div_v = _window_fit(model, np.asarray(y_val, dtype=np.float64),
                                          np.asarray(u_val, dtype=np.float64))
    return ValidationReport(
        estimation=est, validation=val, osa_r2=osa_r2, correlation=corr,
        free_run_diverged=div_e or div_v, validation_osa_r2=val_osa,
        estimation_diverged=div_e, validation_diverged=div_v,
    )


@dataclass(frozen=True)
class IdentifyResult:
    """One offline identification of a recording (the ``identify`` JSON)."""

    input: str
    output: str
    sample_rate_hz: float
    fit: NarxFit
    validation: ValidationReport
    estimate: tuple[int, int]
    validate: tuple[int, int] | None
    excitation: dict[str, Any] | None
    timing_ms: dict[str, float]
    speed_derived: bool = False  # the speed signal was derived from position
    form: str = "level"

    @property
    def model(self) -> NarxModel:
        return self.fit.model

    def to_dict(self) -> dict[str, Any]:
        st = self.fit.model.structure or Structure()
        check = self.fit.data_check
        return {
            "input": self.input, "output": self.output, "sample_rate_hz": self.sample_rate_hz,
            "speed_derived": self.speed_derived and "speed" in (self.input, self.output),
            "form": self.form,
            "structure": {"ny": st.ny, "nu": st.nu, "degree": st.degree, "delay": st.delay,
                          "constant": st.constant, "n_candidates": self.fit.n_candidates},
            "method": self.fit.method, "criterion": self.fit.criterion,
            "dc_removed": self.fit.dc_removed,
            "terms": self.fit.model.terms_json(),
            "sum_err": self.fit.sum_err,
            "greedy_terms": list(self.fit.greedy_terms), "n_swaps": self.fit.n_swaps,
            "estimate": list(self.estimate),
            "validate": list(self.validate) if self.validate else None,
            "validation": self.validation.to_dict(),
            "data_check": check.to_dict() if check else None,
            "excitation": self.excitation,
            "timing_ms": self.timing_ms,
        }


#: How an output enters the model: as measured, or as its increment per sample.
FORMS = ("level", "difference")


def output_increments(x: FloatArray, before: float | None) -> FloatArray:
    """y(k) - y(k-1) of ``x`` (``before`` = the sample before ``x[0]``; None drops x[0])."""
    x = np.asarray(x, dtype=np.float64)
    return np.diff(x) if before is None else np.diff(x, prepend=before)


def _extended(rec: Any, name: str, rng: tuple[int, int], lag: int) -> FloatArray:
    """Samples rng[0]-lag .. rng[1]-1 of a signal (fewer before if the recording starts)."""
    return np.asarray(rec.signal(name)[max(rng[0] - lag, 0) : rng[1]], dtype=np.float64)


def _window_pair(rec: Any, input: str, output: str, rng: tuple[int, int], lag: int,
                 form: str) -> tuple[FloatArray, FloatArray]:
    """Output and input of a window with the lag samples before it; with ``form``
    'difference' the output is its increment per sample (the increment of the recording's
    first sample does not exist: there the window starts one sample later)."""
    y, u = _extended(rec, output, rng, lag), _extended(rec, input, rng, lag)
    if form == "level":
        return y, u
    first = max(rng[0] - lag, 0)
    before = None if first == 0 else float(rec.signal(output)[first - 1])
    dy = output_increments(y, before)
    return dy, u[len(u) - len(dy):]


def _check_range(label: str, rng: tuple[int, int], n: int) -> None:
    from ..errors import DataError

    start, stop = rng
    if not 0 <= start < stop <= n:
        raise DataError(f"{label} range {start}:{stop} is outside the recording (0:{n})")


def _check_grid(rec: Any, label: str, rng: tuple[int, int], lag: int) -> None:
    """A window and the samples feeding its lags must be on one sampling grid."""
    first = max(rng[0] - lag, 0)
    what = f"{label} range {rng[0]}:{rng[1]}"
    if first < rng[0]:
        what += f" (lags from sample {first})"
    check_sampling(np.asarray(rec.t[first : rng[1]]), float(rec.sample_rate_hz), what, first)


def _excitation(u: FloatArray, fs: float) -> dict[str, Any] | None:
    try:
        from .identifiability import excitation_summary
    except ImportError:  # pragma: no cover - module ships with the package
        return None
    summary: Any = excitation_summary(u, fs)
    out: dict[str, Any] = summary.to_dict()
    return out


def _check_validation_data(y: FloatArray, u: FloatArray, output: str, input: str,
                           rng: tuple[int, int], degree: int) -> None:
    """The validation window gets the estimation window's magnitude check: predicting with
    signals of 1e154 overflows as surely as fitting them."""
    from .datacheck import _magnitude

    try:
        _magnitude({output: y, input: u}, degree)
    except DataError as exc:
        raise DataError(f"validation range {rng[0]}:{rng[1]}: {exc}") from exc


def identify_recording(
    rec: Any,
    *,
    input: str = "thrust",
    output: str = "speed",
    config: FitConfig | None = None,
    estimate: tuple[int, int] = (1000, 2000),
    validate: tuple[int, int] | None = (3000, 4000),
    max_lag_corr: int = 20,
    form: str = "level",
) -> IdentifyResult:
    """The paper's protocol on a :class:`~.signals.Recording`: fit on ``estimate``, check the
    model predicted output on ``validate`` (0-based half-open ranges).

    ``form`` 'difference' models the output's increment per sample, y(k) - y(k-1): the
    bounded form of an integrating output (position), whose free run cannot drift away.

    Every sample of each window is a predicted sample: the L samples before a window (L =
    max lag) feed the lags when the recording has them (otherwise the window's own first L).
    """
    t0 = time.perf_counter()
    cfg = config or FitConfig()
    n = len(rec)
    if form not in FORMS:
        from ..errors import DataError

        raise DataError(f"form must be one of {', '.join(FORMS)}, got '{form}'")
    _check_range("estimation", estimate, n)
    if validate is not None:
        _check_range("validation", validate, n)
    lag = cfg.structure.max_lag
    _check_grid(rec, "estimation", estimate, lag)
    if validate is not None:
        _check_grid(rec, "validation", validate, lag)
    y_e, u_e = _window_pair(rec, input, output, estimate, lag, form)
    fs = float(rec.sample_rate_hz)
    fit = fit_narx(y_e, u_e, cfg, fs, input_name=input, output_name=output)
    t1 = time.perf_counter()
    yv = uv = None
    if validate is not None:
        yv, uv = _window_pair(rec, input, output, validate, lag, form)
        _check_validation_data(yv, uv, output, input, validate, cfg.structure.degree)
    report = validate_narx(fit.model, y_e, u_e, yv, uv, max_lag=max_lag_corr)
    t2 = time.perf_counter()
    excitation = _excitation(u_e[min(lag, estimate[0]) :], fs)
    timing = {**fit.timing_ms, "validation": 1e3 * (t2 - t1),
              "total": 1e3 * (time.perf_counter() - t0)}
    return IdentifyResult(input=input, output=output, sample_rate_hz=fs, fit=fit,
                          validation=report, estimate=estimate, validate=validate,
                          excitation=excitation, timing_ms=timing,
                          speed_derived=bool(getattr(rec, "speed_derived", False)), form=form)
