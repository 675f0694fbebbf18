"""Property tests (issue 8): on random finite inputs the bag reader, OFR/iOFR and the GFRFs
never crash, never put NaN in their outputs, and fail only with the project's documented
error types (:class:`~pmsm_sysid.core.errors.PmsmSysidError` subclasses).

The aligner itself has its own property tests (``test/test_align.py``: counts, mutual
nearest matching against brute force, jittered grids with drops, duplicates and shuffles);
here the whole reader is exercised from bytes on disk.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, example, given, settings
from hypothesis import strategies as st
from reliability_helpers import write_messages

from pmsm_sysid.bagio import read_recording
from pmsm_sysid.core.errors import BagError, DataError, PmsmSysidError
from pmsm_sysid.core.frequency.analysis import analyse
from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.selection.identify import FitConfig, fit_narx, validate_narx
from pmsm_sysid.core.terms.model import NarxModel, Structure, Term

SETTINGS = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])

finite = st.floats(allow_nan=False, allow_infinity=False)
moderate = st.floats(-1e6, 1e6, allow_nan=False)


def _no_nan(obj: Any, where: str = "") -> None:
    """Every float in a JSON-like structure is finite (non-finite must have become None)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            _no_nan(v, f"{where}.{k}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _no_nan(v, f"{where}[{i}]")
    elif isinstance(obj, float):
        assert math.isfinite(obj), where


# ------------------------------------------------------------------------------ bag reader


@st.composite
def message_streams(draw: Any) -> list[tuple[str, int, int, float]]:
    """Up to 60 messages per signal: stamps anywhere (duplicates, disorder, jumps), values
    any float (NaN, inf, huge), some signals missing."""
    out = []
    period = draw(st.sampled_from([1_000_000, 2_000_000]))
    for signal in draw(st.sets(st.sampled_from(["thrust", "speed", "position"]), min_size=1)):
        n = draw(st.integers(0, 60))
        base = draw(st.lists(st.integers(0, 80), min_size=n, max_size=n))
        jitter = draw(st.lists(st.integers(-period // 2, period // 2), min_size=n, max_size=n))
        values = draw(st.lists(st.floats(width=64), min_size=n, max_size=n))
        for k, j, v in zip(base, jitter, values, strict=True):
            stamp = max(10**9 + k * period + j, 0)
            out.append((signal, stamp, stamp, v))
    return draw(st.permutations(out))


@SETTINGS
@given(msgs=message_streams(), storage=st.sampled_from(["mcap", "sqlite3"]))
def test_bag_reader_on_random_streams(tmp_path_factory: pytest.TempPathFactory,
                                      msgs: list[tuple[str, int, int, float]],
                                      storage: str) -> None:
    bag = write_messages(tmp_path_factory.mktemp("bag") / "b", msgs, storage=storage)
    try:
        loaded = read_recording(bag)
    except (BagError, DataError) as exc:
        assert "\n" not in str(exc)
        return
    rec, rep = loaded.recording, loaded.report
    assert len(rec) == rep.n_aligned >= 3
    for name in ("t", "thrust", "speed", "position"):
        assert np.all(np.isfinite(getattr(rec, name))), name
    assert np.all(np.diff(rec.t) > 0) and math.isfinite(rec.sample_rate_hz)
    streams = 2 if rep.speed_derived else 3
    assert (rep.n_thrust + rep.n_speed + rep.n_position == streams * rep.n_aligned
            + rep.n_nonfinite + rep.n_duplicates + rep.n_unaligned)


@SETTINGS
@given(cut=st.floats(0.0, 1.0), flips=st.lists(st.tuples(st.floats(0.0, 1.0),
                                                         st.integers(0, 255)), max_size=8),
       storage=st.sampled_from(["mcap", "sqlite3"]))
def test_bag_reader_on_damaged_files(tmp_path_factory: pytest.TempPathFactory, cut: float,
                                     flips: list[tuple[float, int]], storage: str) -> None:
    """A good bag truncated anywhere and with random bytes overwritten: the reader either
    reads it (every value finite) or says in one line what is wrong."""
    msgs = [(s, 10**9 + k * 2_000_000, 10**9 + k * 2_000_000, float(k % 7))
            for k in range(40) for s in ("thrust", "speed", "position")]
    bag = write_messages(tmp_path_factory.mktemp("bag") / "b", msgs, storage=storage)
    data = next(bag.glob("*.mcap" if storage == "mcap" else "*.db3"))
    blob = bytearray(data.read_bytes())
    for where, byte in flips:
        blob[min(int(where * len(blob)), len(blob) - 1)] = byte
    data.write_bytes(bytes(blob[: max(1, int(cut * len(blob)))] if cut < 1 else blob))
    try:
        rec = read_recording(bag).recording
    except (BagError, DataError) as exc:
        assert "\n" not in str(exc) and str(bag) in str(exc)
        return
    assert all(np.all(np.isfinite(rec.signal(s))) for s in ("thrust", "speed", "position"))


# ------------------------------------------------------------------------------------ OFR


@st.composite
def fit_problems(draw: Any) -> tuple[np.ndarray, np.ndarray, FitConfig]:
    ny, nu = draw(st.integers(0, 3)), draw(st.integers(0, 3))
    assume(ny + nu > 0)
    structure = Structure(ny=ny, nu=nu, degree=draw(st.integers(1, 3)),
                          delay=draw(st.integers(1, 2)), constant=draw(st.booleans()))
    config = FitConfig(structure=structure, n_terms=draw(st.integers(1, 6)),
                       criterion=draw(st.sampled_from(["terms", "err", "aic", "bic"])),
                       method=draw(st.sampled_from(["ofr", "iofr"])),
                       remove_dc=structure.constant and draw(st.booleans()))
    n = draw(st.integers(0, 240))
    kind = draw(st.sampled_from(["any", "moderate", "steps", "noise"]))
    if kind == "noise":
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        scale = 10.0 ** draw(st.integers(-150, 150))
        u, y = rng.normal(size=n) * scale, rng.normal(size=n) * scale
    else:
        elems = {"any": finite, "moderate": moderate,
                 "steps": st.sampled_from([-1.0, 0.0, 1.0, 2.5])}[kind]
        u = np.array(draw(st.lists(elems, min_size=n, max_size=n)), dtype=np.float64)
        y = np.array(draw(st.lists(elems, min_size=n, max_size=n)), dtype=np.float64)
    return y, u, config


# found by this test: iOFR's AIC resize once added a term beyond --terms (the maximum)
_AIC_CAP = (np.r_[[-1.0] * 31, 0.0], np.r_[[-1.0] * 29, 0.0, 1.0, -1.0],
            FitConfig(structure=Structure(ny=0, nu=1, degree=2), n_terms=1, criterion="aic"))
# ... and a path with no usable candidate raised numpy's ValueError
_NOTHING = (np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, 1.0]),
            FitConfig(structure=Structure(ny=0, nu=1, degree=1, constant=False), n_terms=1,
                      criterion="aic", remove_dc=False))


@settings(SETTINGS, max_examples=80)
@given(problem=fit_problems())
@example(problem=_AIC_CAP)
@example(problem=_NOTHING)
def test_ofr_on_random_finite_data(problem: tuple[np.ndarray, np.ndarray, FitConfig]) -> None:
    y, u, config = problem
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # an overflow would be a silent NaN
        try:
            fit = fit_narx(y, u, config, sample_rate_hz=500.0)
        except PmsmSysidError as exc:
            assert "\n" not in str(exc)
            event(f"refused: {type(exc).__name__}")
            return
    event("fitted")
    m = fit.model
    assert 1 <= len(m.terms) <= config.n_terms + 1
    assert np.all(np.isfinite(m.estimates)) and np.all(np.isfinite(m.err))
    assert np.all(np.isfinite(fit.residuals)) and math.isfinite(fit.sum_err)
    assert len({t.name for t in m.terms}) == len(m.terms)  # no term twice
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            report = validate_narx(m, y, u, max_lag=2)
        except PmsmSysidError:
            return
    d = report.to_dict()
    for test in d["correlation_tests"].values():
        assert test["max_abs"] is None or 0.0 <= test["max_abs"] <= 1.0 + 1e-9
    if not d["free_run_diverged"]:
        _no_nan(d["estimation"], "estimation")


# ----------------------------------------------------------------------------------- GFRF


@st.composite
def models(draw: Any) -> NarxModel:
    names = draw(st.lists(st.sampled_from(
        ["y(k-1)", "y(k-2)", "y(k-4)", "u(k-1)", "u(k-3)", "y(k-1)^2", "u(k-1)^2",
         "y(k-1)u(k-2)", "u(k-1)^3", "y(k-2)u(k-1)^2", "y(k-1)^2u(k-1)", "y(k-3)^3", "const"]),
        min_size=1, max_size=6, unique=True))
    coefficients = st.one_of(st.floats(-2.0, 2.0), st.floats(-1e6, 1e6))
    values = [draw(coefficients) for _ in names]
    return NarxModel(terms=tuple(Term.parse(n) for n in names),
                     estimates=np.array(values, dtype=np.float64),
                     sample_rate_hz=draw(st.sampled_from([500.0, 1000.0, 1.0])))


@SETTINGS
@given(model=models(), f=st.lists(st.floats(-0.5, 0.5), min_size=1, max_size=3))
def test_gfrf_on_random_models(model: NarxModel, f: list[float]) -> None:
    g = Gfrf.from_model(model)
    h = g.h(*f)
    poles = g.poles()
    on_circle = bool(poles.size) and bool(np.min(np.abs(np.abs(poles) - 1.0)) < 1e-9)
    assert np.all(np.isfinite(h)) or on_circle, (h, f)
    event("stable" if g.stable else "unstable")
    res = analyse(model, at=[f], orders=(1, 2)).to_dict()
    _no_nan(res, "gfrf")  # non-finite values are documented nulls, never NaN
    assert res["stable"] == bool(np.all(np.abs(poles) < 1.0))


@SETTINGS
@given(f=st.lists(st.one_of(finite, st.just(float("nan")), st.just(float("inf"))),
                  min_size=0, max_size=5))
def test_gfrf_frequencies_out_of_range_are_gfrf_errors(f: list[float]) -> None:
    g = Gfrf.from_model(NarxModel.from_terms({"y(k-1)": 0.5, "u(k-1)": 1.0, "u(k-1)^2": 0.2}))
    try:
        h = g.h(*f)
    except PmsmSysidError as exc:
        assert "\n" not in str(exc)
        return
    assert 1 <= len(f) <= 4 and all(abs(x) <= 0.5 for x in f)
    assert np.all(np.isfinite(h))


def test_property_helpers_see_nan() -> None:
    with pytest.raises(AssertionError):
        _no_nan({"a": [1.0, {"b": float("nan")}]})
    _no_nan({"a": [1.0, None, {"b": 2}]})
    # infinities too, inside tuples, and the failure names where the value is
    for bad in (float("inf"), -float("inf")):
        with pytest.raises(AssertionError, match=r"(?m)^\.a\[1\]\.b\[0\]$"):
            _no_nan({"a": (1.0, {"b": [bad]})})
