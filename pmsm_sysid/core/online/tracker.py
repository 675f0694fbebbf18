"""What the identifier does with each window: fit, cross-validate, watch for plant changes.

For every output (``speed``, ``position``) and window j (samples [a, b), with the L = max lag
samples before a feeding the lags, exactly as ``identify --estimate a:b`` does):

1. **Fit** by OFR/iOFR (:func:`.identify.fit_narx`) and validate on the window itself
   (:func:`.identify.validate_narx`: model predicted output, Eq. 12 of Liu et al. (2005);
   correlation tests, Eq. 13). The model JSON has the ``identify`` shape (with the input's
   ``excitation`` summary, so the GFRF node can judge which peaks the data support) plus ``window``,
   ``fit_time_ms``, ``model_id``; its ``validation.validation`` is null: independent data
   come later.
2. **Cross-validate** every earlier model on the first window that starts at or after that
   model's window ends (no shared samples; with the defaults, the model of window j-4): free
   run (Eq. 12) NRMSE/R^2 and one-step-ahead R^2 on the new window, and the five correlation
   tests (Eq. 13) of the one-step residuals on it, with their 95 % bands. Pass = free-run
   R^2 >= ``min_r2`` on the new window without divergence, and every correlation test passed
   on the model's estimation residuals (the model validity tests as Billings & Voon define
   them, Section II.3 of Liu et al. (2005)). The tests on the new window are published beside, as
   information: a NARX model has no noise model, so coloured process noise shows there first.
3. **Change features** (:mod:`.change`), judged for a window that directly follows the
   previous fitted one (when fits cannot keep up and windows are skipped, detection pauses:
   the stream of models it is calibrated on has holes) of an output whose models reproduce
   their own windows (median free-run R^2 of the recent windows >= ``change_min_r2``, 0.99;
   otherwise the window is ``unjudged``: e.g. a model of a plant the structure cannot
   describe, whose features wander), and only under the excitation of the reference window
   (the first after a (re)start): the Bhattacharyya overlap of the window's input spectrum
   with the reference's must reach 0.95 (:data:`.change.SAME_EXCITATION`), because models
   fitted to different bands differ with no change in the plant. A window under another
   excitation (a chirp elsewhere in its sweep) is ``unjudged`` without breaking the run of
   comparable windows: under a 10 s chirp the detector compares the windows at the same
   phase of the sweep, 10 s apart. The features: the new model's
   free-run RMS error on its own window, over the output's std in the first window fitted
   (one scale: the output's own spread follows the window's input; a window spanning a
   change fits worse); the
   out-of-sample error of the previous windows' models on the ``hop`` newest samples (free
   run over the window, NRMSE of the new samples; the smaller of the last two models': one
   odd fit, e.g. spurious cross terms y(k-i)u(k-j) that cancel on its own window and not on
   new amplitudes, would otherwise score in the next window too, and one odd fit must not
   make two windows in a row; a plant change defeats both models);
   the gain and phase of the new model's H1 (Eq. 7 of Liu et al. 2005) at the reference excitation
   frequency f0 (the strongest input line of the first window after a (re)start; the phase
   relative to its value there, wrapped to (-pi, pi]); the Jaccard distance between
   consecutive term sets; and the harmonic content of the window's output, the energy at
   2..5 x the window's strongest input line relative to the line itself (dB) — what the
   nonlinear GFRFs H2/H3 transfer to harmonics (Section V of Liu et al. 2005), e.g. when cogging
   appears. The harmonic content is observed only when the input has none of its own there
   (a tone: :data:`.features.INPUT_HARMONICS_MAX_DB`); under a random input (APRBS, PRBS, multisine,
   broadband) the output's energy at those lines is what the input put there, which differs
   from window to window with no change in the plant, so the feature is left out (NaN).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, PmsmSysidError
from ..selection.identifiability import excitation_summary
from ..selection.identify import (
    FORMS,
    METHODS,
    FitConfig,
    IdentifyResult,
    fit_narx,
    output_increments,
    validate_narx,
)
from ..terms.model import NarxModel, Structure
from ..validation.correlation import correlation_tests, fit_metrics
from ..validation.prediction import one_step_ahead, simulate
from .change import (
    SAME_EXCITATION,
    ChangeConfig,
    ChangeDecision,
    ChangeDetector,
    FeatureSpec,
    input_spectrum,
    jaccard_distance,
    spectral_overlap,
)
from .features import (
    best_newest_error,
    dominant_frequency,
    h1_features,
    plant_harmonics_db,
    wrap_phase,
)
from .streaming import NS_PER_S
from .windows import Window

FloatArray = NDArray[np.float64]
OUTPUTS = ("speed", "position")

#: Features watched by the change detector (floors: see ``test/test_change.py``).
CHANGE_FEATURES = (
    FeatureSpec("xval_nrmse", one_sided=True, floor=1e-3, rel_floor=0.1),
    FeatureSpec("h1_gain_db", floor=0.02),
    FeatureSpec("h1_phase_rad", floor=0.05),
    FeatureSpec("term_jaccard", one_sided=True, floor=0.05),
    FeatureSpec("harmonics_db", floor=1.0),
    FeatureSpec("fit_nrmse", one_sided=True, floor=1e-3, rel_floor=0.1),
)


@dataclass(frozen=True)
class OutputConfig:
    """One identified relation: ``input`` -> ``output`` with its fit settings."""

    output: str
    fit: FitConfig
    input: str = "thrust"
    form: str = "level"  # or "difference": the output's increment per sample

    @property
    def history(self) -> int:
        """Samples before a window that its first rows need (one more for an increment)."""
        return self.fit.structure.max_lag + (self.form == "difference")


@dataclass(frozen=True)
class TrackerConfig:
    outputs: tuple[OutputConfig, ...]
    window: int = 1000
    hop: int = 250
    min_r2: float = 0.9
    change_min_r2: float = 0.99
    corr_max_lag: int = 20
    change: ChangeConfig = field(default_factory=ChangeConfig)

    def __post_init__(self) -> None:
        if not self.outputs:
            raise DataError("the tracker needs at least one output")
        if self.window < 2 or self.hop < 1:
            raise DataError(f"need window >= 2 and hop >= 1 (got {self.window}, {self.hop})")
        for name in ("min_r2", "change_min_r2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value <= 1):
                raise DataError(f"{name} must be a number <= 1, got {value}")
        if self.corr_max_lag < 1 or self.window < 4 * self.corr_max_lag:
            raise DataError(f"the correlation tests need window >= 4 x {self.corr_max_lag}")
        for o in self.outputs:  # refused at start, rather than silently fitting nothing
            lag = o.fit.structure.max_lag
            n_params = o.fit.n_terms + (1 if o.fit.dc_removed else 0)
            if self.window < lag + 2 * n_params:
                raise DataError(
                    f"{o.output}: a window of {self.window} samples can never fit maximum lag "
                    f"{lag} and {n_params} parameters (it needs at least {lag + 2 * n_params}: "
                    "lag + 2 x parameters); raise window or lower the lags or terms")

    @property
    def history(self) -> int:
        return max(o.history for o in self.outputs)


def tracker_config(p: Mapping[str, Any]) -> TrackerConfig:
    """Tracker settings from the identifier node's flat parameters (see ``DEFAULTS``)."""
    outs = list(p["outputs"])
    if not outs or any(o not in OUTPUTS for o in outs) or len(set(outs)) != len(outs):
        raise DataError(f"outputs must be distinct names from {OUTPUTS}, got {outs}")
    if p["method"] not in METHODS:
        raise DataError(f"method must be one of {METHODS}, got '{p['method']}'")
    cfgs = []
    for o in outs:
        st = Structure(ny=int(p[f"{o}.ny"]), nu=int(p[f"{o}.nu"]),
                       degree=int(p[f"{o}.degree"]), delay=int(p[f"{o}.delay"]))
        form = str(p.get(f"{o}.form", "level"))
        if form not in FORMS:
            raise DataError(f"{o}.form must be one of {', '.join(FORMS)}, got '{form}'")
        cfgs.append(OutputConfig(o, FitConfig(structure=st, n_terms=int(p[f"{o}.terms"]),
                                              criterion=str(p["criterion"]),
                                              method=str(p["method"])), form=form))
    change = ChangeConfig(baseline=int(p["change.baseline"]), warmup=int(p["change.warmup"]),
                          s_confirm=float(p["change.s_confirm"]),
                          holdoff=max(0, int(p["window"]) // max(1, int(p["hop"])) - 1))
    return TrackerConfig(tuple(cfgs), window=int(p["window"]), hop=int(p["hop"]),
                         min_r2=float(p["min_r2"]), change_min_r2=float(p["change.min_r2"]),
                         change=change)


@dataclass(frozen=True)
class WindowResult:
    """Everything one window produced: model JSONs, cross-validations, change events,
    detector states and per-output errors."""

    seq: int
    start_stamp: float
    end_stamp: float
    models: tuple[dict[str, Any], ...]
    validations: tuple[dict[str, Any], ...]
    changes: tuple[dict[str, Any], ...]
    decisions: tuple[dict[str, Any], ...]
    errors: tuple[dict[str, Any], ...]
    process_ms: float


@dataclass
class _Held:
    """A fitted model waiting for its independent validation window."""

    model: NarxModel
    model_id: str
    stop_index: int
    window: dict[str, Any]
    estimation_tests: dict[str, Any]
    estimation_tests_pass: bool


class _OutputTrack:
    """State kept per output between windows (bounded)."""

    def __init__(self, cfg: OutputConfig, tc: TrackerConfig, max_held: int) -> None:
        self.cfg = cfg
        self.detector = ChangeDetector(CHANGE_FEATURES, tc.change)
        self.previous: NarxModel | None = None
        self.previous_stop: int | None = None
        self.before_previous: NarxModel | None = None  # the model of the window before that
        self.ref_freq: float | None = None
        self.ref_phase: float | None = None
        self.ref_spectrum: FloatArray | None = None
        self.ref_spread: float | None = None  # output std over the first window fitted
        self.r2: deque[float] = deque(maxlen=tc.change.baseline)
        self.held: deque[_Held] = deque(maxlen=max_held)


def window_info(w: Window, fs: float) -> dict[str, Any]:
    return {"seq": w.seq, "start_stamp": w.start_stamp, "end_stamp": w.end_stamp,
            "start_index": w.start_index, "stop_index": w.stop_index,
            "n_samples": w.stop_index - w.start_index, "sample_rate_hz": fs,
            "speed_derived": w.speed_derived}


def window_rate(w: Window) -> float:
    """Sample rate of a window from its stamps (median step), as ``identify`` reads it."""
    return float(NS_PER_S / np.median(np.diff(w.stamps_ns)))


class WindowTracker:
    """Turns windows into results; call :meth:`process` from one thread at a time."""

    def __init__(self, config: TrackerConfig) -> None:
        self.config = config
        # models wait window/hop windows for independent data; more only after skips
        max_held = config.window // config.hop + 2
        self._tracks = {o.output: _OutputTrack(o, config, max_held) for o in config.outputs}

    @property
    def history(self) -> int:
        return self.config.history

    def process(self, w: Window) -> WindowResult:
        """Fit, cross-validate and judge every output on window ``w``.

        A bad window for one output (e.g. insufficient excitation, a failed fit) is reported
        in ``errors`` and does not stop the other outputs.
        """
        t0 = time.perf_counter()
        fs = window_rate(w)
        info = window_info(w, fs)
        acc: dict[str, list[dict[str, Any]]] = {
            "models": [], "validations": [], "changes": [], "decisions": [], "errors": []}
        for name, track in self._tracks.items():
            try:
                self._one(track, w, fs, info, acc)
            except PmsmSysidError as exc:
                acc["errors"].append({"output": name, "model_id": f"{name}/{w.seq}",
                                      "window": info, "error": f"{type(exc).__name__}: {exc}"})
        return WindowResult(w.seq, w.start_stamp, w.end_stamp,
                            **{k: tuple(v) for k, v in acc.items()},
                            process_ms=1e3 * (time.perf_counter() - t0))

    def _one(self, track: _OutputTrack, w: Window, fs: float, info: dict[str, Any],
             acc: dict[str, list[dict[str, Any]]]) -> None:
        name = track.cfg.output
        y, u = self._series(w, track.cfg)
        acc["validations"].extend(self._cross_validate(track, w, y, u))
        model_json, model = self._fit(track.cfg, y, u, fs, info)
        acc["models"].append(model_json)
        est = model_json["validation"]["estimation"]
        feats = self._features(track, w, model, y, u, est)
        r2 = est["r2"] if est["r2"] is not None and not est["free_run_diverged"] else -math.inf
        track.r2.append(float(r2))
        follows = track.previous_stop == w.stop_index - self.config.hop
        same = self._same_excitation(track, w, u)
        monitored = (follows and len(track.r2) >= 3
                     and float(np.median(track.r2)) >= self.config.change_min_r2)
        if monitored and not same:  # not comparable: the detector neither judges nor forgets
            decision = ChangeDecision(w.seq, "unjudged")
        else:
            decision = track.detector.update(w.seq, feats if monitored else {})
        if decision.changed:
            track.ref_freq = track.ref_spectrum = None
        decision = replace(decision, values=feats)
        ident = {"output": name, "model_id": model_json["model_id"]}
        acc["decisions"].append({**ident, **decision.to_dict()})
        if decision.changed:
            acc["changes"].append({**ident, "window": info, "reasons": list(decision.reasons),
                                   "z": decision.z, "values": decision.values})
        val = model_json["validation"]
        track.held.append(_Held(model, model_json["model_id"], w.stop_index, info,
                                val["correlation_tests"], bool(val["correlation_all_pass"])))
        track.before_previous = track.previous if follows else None
        track.previous, track.previous_stop = model, w.stop_index

    # -- pieces -----------------------------------------------------------------------
    @staticmethod
    def _same_excitation(track: _OutputTrack, w: Window, u: FloatArray) -> bool:
        """Is the window's input spectrum that of the reference window (the first after a
        (re)start)? Models are compared only under the same excitation: a sweep moves them
        with no change in the plant."""
        spec = input_spectrum(u[-(w.stop_index - w.start_index):])
        if track.ref_spectrum is None:
            track.ref_spectrum = spec
        return spectral_overlap(spec, track.ref_spectrum) >= SAME_EXCITATION

    def _series(self, w: Window, cfg: OutputConfig) -> tuple[FloatArray, FloatArray]:
        """Output and input with the structure's L lag samples before the window (the
        output as its increments when the output's form is 'difference')."""
        lag = cfg.fit.structure.max_lag
        first = w.history - lag
        y = w.signal(cfg.output, with_history=True)
        u = w.signal(cfg.input, with_history=True)[first:]
        if cfg.form == "difference":
            return output_increments(y[first - 1:], None), u
        return y[first:], u

    def _fit(self, cfg: OutputConfig, y: FloatArray, u: FloatArray, fs: float,
             info: dict[str, Any]) -> tuple[dict[str, Any], NarxModel]:
        """Fit and self-validate one output; the JSON is :class:`IdentifyResult`'s (the
        ``identify`` verb's, ``estimate`` = the window's sample indices) plus the window."""
        t0 = time.perf_counter()
        fit = fit_narx(y, u, cfg.fit, fs, input_name=cfg.input, output_name=cfg.output)
        report = validate_narx(fit.model, y, u, max_lag=self.config.corr_max_lag)
        lag = cfg.fit.structure.max_lag
        result = IdentifyResult(
            input=cfg.input, output=cfg.output, sample_rate_hz=fs, fit=fit, validation=report,
            estimate=(info["start_index"], info["stop_index"]), validate=None,
            excitation=excitation_summary(u[lag:], fs).to_dict(), timing_ms=fit.timing_ms,
            speed_derived=bool(info.get("speed_derived")), form=cfg.form)
        out = {**result.to_dict(), "window": info, "model_id": f"{cfg.output}/{info['seq']}",
               "fit_time_ms": 1e3 * (time.perf_counter() - t0)}
        return out, fit.model

    def _cross_validate(self, track: _OutputTrack, w: Window, y: FloatArray,
                        u: FloatArray) -> list[dict[str, Any]]:
        out = []
        while track.held and track.held[0].stop_index <= w.start_index:
            held = track.held.popleft()
            out.append(self._validation(held, w, y, u))
        return out

    def _validation(self, held: _Held, w: Window, y: FloatArray,
                    u: FloatArray) -> dict[str, Any]:
        """Free run and correlation tests of a held model on window ``w`` (see module doc)."""
        m = held.model
        first = len(y) - (w.stop_index - w.start_index) - m.max_lag
        yv, uv = y[first:], u[first:]
        lag = m.max_lag
        run = simulate(m, uv, yv[:lag])
        free = fit_metrics(yv[lag:], run.y[lag:])
        osa = one_step_ahead(m, yv, uv)
        corr = correlation_tests((yv - osa)[lag:], uv[lag:], max_lag=self.config.corr_max_lag)
        ok = (not run.diverged) and free.r2 >= self.config.min_r2 and held.estimation_tests_pass
        return {"output": m.output_name, "model_id": held.model_id, "model_window": held.window,
                "validated_on": {"seq": w.seq, "start_stamp": w.start_stamp,
                                 "end_stamp": w.end_stamp},
                "free_run": {**free.to_dict(), "diverged": run.diverged},
                "osa_r2": fit_metrics(yv[lag:], osa[lag:]).r2,
                "correlation_tests": held.estimation_tests,
                "correlation_tests_validation": corr.to_dict(), "min_r2": self.config.min_r2,
                "pass": bool(ok)}

    def _features(self, track: _OutputTrack, w: Window, model: NarxModel, y: FloatArray,
                  u: FloatArray, est: Mapping[str, Any]) -> dict[str, float]:
        """The change features of this window (module docstring, item 3)."""
        u_win = u[-(w.stop_index - w.start_index):]
        if track.ref_freq is None:
            track.ref_freq, track.ref_phase = dominant_frequency(u_win), None
        feats = h1_features(model, track.ref_freq)
        if track.ref_phase is None and math.isfinite(feats["h1_phase_rad"]):
            track.ref_phase = feats["h1_phase_rad"]
        feats["h1_phase_rad"] = wrap_phase(feats["h1_phase_rad"] - (track.ref_phase or 0.0))
        y_win = y[len(y) - len(u_win):]
        feats["harmonics_db"] = plant_harmonics_db(y_win, u_win)
        feats["fit_nrmse"] = self._fit_error(track, y[model.max_lag:], est)
        if track.previous is not None and track.previous_stop == w.stop_index - self.config.hop:
            recent = [m for m in (track.previous, track.before_previous) if m is not None]
            feats["xval_nrmse"] = best_newest_error(recent, y, u, self.config.hop)
            feats["term_jaccard"] = jaccard_distance(model.term_names, track.previous.term_names)
        return feats

    @staticmethod
    def _fit_error(track: _OutputTrack, y_run: FloatArray, est: Mapping[str, Any]) -> float:
        """The model's free-run RMS error on its own window (``y_run``: the samples its
        free-run NRMSE ``est`` was taken over) over the output's std in the first window
        fitted (one scale for the run), not this window's: the error of a good model is the
        response to the plant's noise, the same in every window, while the output's spread
        follows the window's input (under APRBS, +-40 % from window to window). Inf if the
        free run diverged."""
        nrmse = est["nrmse"]
        if nrmse is None or est["free_run_diverged"]:
            return math.inf
        spread = float(np.std(y_run))
        if track.ref_spread is None:
            track.ref_spread = spread
        return float(nrmse) * spread / track.ref_spread if track.ref_spread > 0 else math.nan
