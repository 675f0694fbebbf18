"""What a new user's first ``pmsm-sysid run`` identifies, without ROS.

The default plant, excitation and identifier parameters go through the identifier's own data
path (:func:`pmsm_sysid.core.online.livesim.simulated_windows` + the :class:`WindowTracker`), as
``run --clock sim`` feeds them when no window is skipped: the models must be true of the
motor, the tool's own checks quiet, and the change detector silent on a stationary plant yet
quick on a real change.
"""

from __future__ import annotations

import copy
import hashlib
import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from pmsm_sysid.cli.run_verdict import verdict
from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.online.livesim import simulated_windows
from pmsm_sysid.core.online.tracker import WindowTracker, tracker_config
from pmsm_sysid.core.physics.plant import Plant, load_plant
from pmsm_sysid.core.terms.model import NarxModel
from pmsm_sysid.nodes.defaults import IDENTIFIER_DEFAULTS as DEFAULTS

# one test process runs them all (make test: --dist loadgroup), so the shared runs are fitted
# once
pytestmark = pytest.mark.xdist_group("default_run")


def _run_defaults() -> tuple[str, str]:
    """The plant and excitation ``pmsm-sysid run`` uses when given no option."""
    import argparse

    from pmsm_sysid.cli import run as run_cli

    p = argparse.ArgumentParser()
    run_cli.add_arguments(p)
    args = p.parse_args([])
    return args.plant, args.excitation


def _track(plant: Plant, excitation: str, seconds: float,
           switch: dict[int, Plant] | None = None,
           params: dict[str, Any] | None = None) -> dict[str, Any]:
    """What the tracker reports for ``seconds`` of the motor under ``excitation`` (with
    ``switch``: the plant taking over at a sample). The default motor's stationary runs
    are shared (:class:`_Stationary`): a run that only needs a prefix of one takes its
    results; a run with a switch takes the tracker as it was on the last window before the
    switch, after checking that its windows up to there are the stationary run's, bit for
    bit, and fits only the windows after."""
    n = round(seconds * plant.sample_rate_hz)
    cfg = tracker_config({**DEFAULTS, **(params or {})})
    switch = switch or {}
    shared = _Stationary.of(excitation) if plant == load_plant("drive") and not params \
        else None
    if shared is not None and not switch:
        return shared.results(n)
    first = min(switch, default=n)
    resume = (first // cfg.hop) * cfg.hop  # windows ending here hold no sample of the switch
    tracker, out = WindowTracker(cfg), _empty()
    if shared is not None and resume in _Stationary.RESUME_AT:
        tracker, out = shared.resume(resume)
    for w in simulated_windows(plant, excitation, n, window=cfg.window, hop=cfg.hop,
                               history=tracker.history, switch=switch):
        if shared is not None and w.stop_index <= resume and resume in _Stationary.RESUME_AT:
            assert shared.digest(w.stop_index) == _digest(w), w.stop_index  # same windows
            continue
        _add(out, w, tracker.process(w))
    return out


def _empty() -> dict[str, Any]:
    return {"models": [], "validations": [], "changes": [], "errors": []}


def _add(out: dict[str, Any], w: Any, result: Any) -> None:
    for key in out:
        out[key] += [(w.stop_index, x) for x in getattr(result, key)]


def _digest(w: Any) -> str:
    return hashlib.sha1(w.values.tobytes() + w.stamps_ns.tobytes()).hexdigest()


class _Stationary:
    """One run of the default motor under one excitation, fitted once per test process
    and extended as tests need more of it; keeps each window's digest and the tracker as it
    was at the windows the change tests resume from (``RESUME_AT``)."""

    SECONDS = 60.0
    RESUME_AT = (10000, 14000)

    @classmethod
    def of(cls, excitation: str) -> _Stationary:
        if excitation not in _RUNS:
            _RUNS[excitation] = cls(excitation)
        return _RUNS[excitation]

    def __init__(self, excitation: str) -> None:
        plant = load_plant("drive")
        self.tracker = WindowTracker(tracker_config(DEFAULTS))
        self.windows = simulated_windows(
            plant, excitation, round(self.SECONDS * plant.sample_rate_hz),
            window=self.tracker.config.window, hop=self.tracker.config.hop,
            history=self.tracker.history)
        self.out, self.stop, self.digests = _empty(), 0, {}
        self.saved: dict[int, tuple[WindowTracker, dict[str, Any]]] = {}

    def _extend(self, n: int) -> None:
        hop = self.tracker.config.hop
        while self.stop + hop <= n:
            w = next(self.windows)
            _add(self.out, w, self.tracker.process(w))
            self.stop, self.digests[w.stop_index] = w.stop_index, _digest(w)
            if w.stop_index in self.RESUME_AT:
                self.saved[w.stop_index] = copy.deepcopy((self.tracker, self.out))

    def results(self, n: int) -> dict[str, Any]:
        """The results of the first ``n`` samples (a copy)."""
        self._extend(n)
        return {k: [(stop, x) for stop, x in v if stop <= n] for k, v in self.out.items()}

    def digest(self, stop: int) -> str:
        self._extend(stop)
        return self.digests[stop]

    def resume(self, stop: int) -> tuple[WindowTracker, dict[str, Any]]:
        """A copy of the tracker and the results right after the window ending at ``stop``."""
        self._extend(stop)
        return copy.deepcopy(self.saved[stop])


_RUNS: dict[str, _Stationary] = {}


def _summary_of(got: dict[str, Any]) -> dict[str, Any]:
    """The parts of a run summary the verdict reads, from the tracked results."""
    vals = [v for _, v in got["validations"]]
    models = {m["output"]: m for _, m in got["models"]}
    counts: dict[str, list[int]] = {}
    for v in vals:
        c = counts.setdefault(v["output"], [0, 0])
        c[0] += bool(v["pass"])
        c[1] += 1
    return {"last_models": models, "last_validations": {v["output"]: v for v in vals},
            "validation_counts": counts, "change_events": [c for _, c in got["changes"]],
            "errors": [e for _, e in got["errors"]], "samples_received": 1,
            "samples_dropped": 0, "samples_missing": 0, "windows_skipped": 0}


def _true_h1(plant: Plant, f_norm: np.ndarray) -> np.ndarray:
    """The mass-viscous motor's speed response to thrust held over each sample (ZOH)."""
    a = math.exp(-plant.viscous_n_per_mps / plant.sample_rate_hz / plant.mass_kg)
    b = (1 - a) / plant.viscous_n_per_mps
    z = np.exp(2j * np.pi * f_norm)
    result: np.ndarray = b / (z - a)
    return result


def _gain_and_corner(h1: Any) -> tuple[float, float]:
    """|H1(0)| and the frequency (cycles/sample) where |H1| falls to |H1(0)|/sqrt(2)."""
    f = np.linspace(0.0, 0.05, 50001)
    g = np.abs(h1(f))
    return float(g[0]), float(f[np.argmax(g < g[0] / math.sqrt(2))])


@pytest.mark.slow
@pytest.mark.timeout(1200)  # CPU-bound fits (56 windows x 2 outputs): slow on a loaded machine
def test_the_default_run_is_true_of_the_motor_and_quiet() -> None:
    plant_name, excitation = _run_defaults()
    assert (plant_name, excitation) == ("drive", "broadband")
    plant = load_plant(plant_name)
    assert plant.noise is not None and plant.noise.speed_std > 0  # realistic, not ideal
    got = _track(plant, excitation, 30.0)
    assert got["errors"] == [] and got["changes"] == []
    for _, m in got["models"]:
        assert m["data_check"]["warnings"] == [], m["data_check"]
        assert m["data_check"]["pe_order"] >= m["data_check"]["pe_required"]
    for output in ("speed", "position"):
        vals = [v for _, v in got["validations"] if v["output"] == output]
        assert len(vals) >= 50
        # every free run stays bounded and close (position: as its increments per sample)
        assert all(not v["free_run"]["diverged"] and v["free_run"]["r2"] > 0.98 for v in vals)
        # the correlation tests reject a correct model in about 5 % of windows
        assert sum(v["pass"] for v in vals) >= 0.9 * len(vals), output
        assert vals[-1]["pass"], vals[-1]  # what the run's summary line reports
    # the run's verdict: pass, judged by the windows' pass rate (chance failures allowed)
    v = verdict(_summary_of(got))
    assert v["status"] == "pass", v
    # the speed models' H1 is the motor's: gain 1/B and corner B/(2 pi M)
    g_true, f_true = _gain_and_corner(lambda f: _true_h1(plant, f))
    speed = [NarxModel.from_dict(m) for _, m in got["models"] if m["output"] == "speed"]
    est = np.array([_gain_and_corner(Gfrf.from_model(m).h1) for m in speed])
    err = est / np.array([g_true, f_true]) - 1.0
    assert np.all(np.abs(np.median(err, axis=0)) < 0.02), np.median(err, axis=0)
    assert np.all(np.abs(err) < 0.1), np.abs(err).max(axis=0)


@pytest.mark.slow
@pytest.mark.timeout(1200)  # CPU-bound, as above
def test_a_model_too_small_for_the_plant_fails_the_run_though_its_free_run_holds() -> None:
    """Position models of 4 terms (the default 15) free-run with R2 > 0.98 on the next
    window, yet their residuals are not white: every window fails the correlation test ee,
    far more than the 1 in 20 a correct model fails, and the verdict says FAIL by the
    binomial test (not by the free run)."""
    got = _track(load_plant("drive"), "broadband", 10.0,
                 params={"outputs": ["position"], "position.terms": 4})
    vals = [v for _, v in got["validations"]]
    assert len(vals) >= 10 and all(v["free_run"]["r2"] > 0.98 for v in vals)
    v = verdict(_summary_of(got))
    assert v["status"] == "FAIL", v
    n = len(vals)
    failed = sum(not x["pass"] for x in vals)
    assert failed >= n - 1 and v["windows"]["position"]["p_value"] < 1e-6
    assert v["failures"][0].startswith(f"position validation FAIL: {failed} of {n} windows "
                                       "failed, more than the 1 in 20 a correct model fails")


@pytest.mark.slow
@pytest.mark.timeout(1200)  # CPU-bound, as above
@pytest.mark.parametrize("excitation", ["broadband", "paper-speed", "aprbs"])
def test_no_false_alarm_on_the_stationary_default_motor(excitation: str) -> None:
    """One minute of data (about 220 judged windows per output) of the default plant; the
    hour-long figures are bench/change_false_alarms.py's."""
    got = _track(load_plant("drive"), excitation, 60.0)
    assert got["changes"] == [] and got["errors"] == []


@pytest.mark.slow
@pytest.mark.timeout(1200)  # CPU-bound, as above
@pytest.mark.parametrize("excitation", ["broadband", "paper-speed"])
@pytest.mark.parametrize("kind", ["mass", "cogging"])
def test_a_real_change_is_reported_on_both_outputs(excitation: str, kind: str) -> None:
    """Mass +20 % or cogging (plants/cogging.yaml's block) from sample 10100: the first window
    holding new data ends at 10250; each output reports the change by 10750, once."""
    plant = load_plant("drive")
    after = (replace(plant, mass_kg=1.2 * plant.mass_kg) if kind == "mass"
             else plant.with_effects(cogging=load_plant("plants/cogging.yaml").cogging))
    got = _track(plant, excitation, 30.0, switch={10100: after})
    assert got["errors"] == []
    for output in ("speed", "position"):
        at = [stop for stop, c in got["changes"] if c["output"] == output]
        assert len(at) == 1 and 10250 <= at[0] <= 10750, (output, at)


@pytest.mark.slow
@pytest.mark.timeout(1200)  # CPU-bound, as above
@pytest.mark.parametrize("kind", ["mass", "viscous"])
def test_a_real_change_under_aprbs_is_reported_once(kind: str) -> None:
    """APRBS windows differ from each other in amplitude distribution (level holds of
    10-100 samples over a 20 s sequence), yet mass +30 % or viscous friction x2 from sample
    14100 (the first window holding new data ends at 14250) is reported by each output by
    14750, and only once in the 20 s after, while the detector relearns the new regime."""
    plant = load_plant("drive")
    after = (replace(plant, mass_kg=1.3 * plant.mass_kg) if kind == "mass"
             else replace(plant, viscous_n_per_mps=2.0 * plant.viscous_n_per_mps))
    got = _track(plant, "aprbs", 34.2, switch={14100: after})
    assert got["errors"] == []
    for output in ("speed", "position"):
        at = [stop for stop, c in got["changes"] if c["output"] == output]
        assert len(at) == 1 and 14250 <= at[0] <= 14750, (output, at)


def test_position_in_difference_form_stays_bounded_where_its_level_does_not() -> None:
    """The integrating position, modelled as its increment per sample, free-runs within the
    validation window; the same structure on the level does worse (measured: R2 0.982 against
    0.996 over 2 s), and only gets worse with time: its integrator pole, estimated a hair
    off 1, lets the free-run error grow without bound."""
    from pmsm_sysid.core.errors import DataError
    from pmsm_sysid.core.physics.excitation import make_excitation
    from pmsm_sysid.core.physics.motor import simulate
    from pmsm_sysid.core.selection.identify import FitConfig, identify_recording
    from pmsm_sysid.core.terms.model import Structure

    plant = load_plant("drive")
    rec = simulate(plant, make_excitation("broadband", 5000, plant.sample_rate_hz), seed=3)
    cfg = FitConfig(structure=Structure(ny=10, nu=10, degree=1, delay=1), n_terms=15)
    fits = {form: identify_recording(rec, output="position", config=cfg, form=form,
                                     estimate=(1000, 2000), validate=(3000, 4000))
            for form in ("difference", "level")}
    diff = fits["difference"].to_dict()
    assert diff["form"] == "difference" and diff["data_check"]["warnings"] == []
    free, level = fits["difference"].validation, fits["level"].validation
    assert free.validation is not None and level.validation is not None
    assert not free.validation_diverged and free.validation.r2 > 0.99
    assert level.validation_diverged or level.validation.r2 < free.validation.r2
    with pytest.raises(DataError, match="form must be one of level, difference"):
        identify_recording(rec, output="position", config=cfg, form="ratio")
    with pytest.raises(DataError, match=r"position\.form must be one of"):
        tracker_config({**DEFAULTS, "position.form": "ratio"})
