"""The package's typed messages (``msg_schemas/*.msg``) built from the identify/gfrf JSON.

On the wire the package publishes standard types (``std_msgs/String`` carrying the JSON, see
:mod:`pmsm_sysid.topics`); these helpers give the same content as ``pmsm_sysid/msg/NarxModel``,
``GfrfRidges`` and ``ValidationStats`` CDR bytes, e.g. to store typed copies in a bag with
:class:`~pmsm_sysid.bagio.BagRecorder` (the bag embeds the definitions).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..core.errors import BagError
from .common import typestore

PKG = "pmsm_sysid/msg/"
CORRELATION_TESTS = ("ee", "ue", "u2e", "u2e2", "e_eu")


def _time(ns: int) -> Any:
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return typestore().types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header(ns: int, frame_id: str) -> Any:
    return typestore().types["std_msgs/msg/Header"](stamp=_time(ns), frame_id=frame_id)


def _f(obj: Mapping[str, Any], key: str) -> float:
    value = obj.get(key)
    return math.nan if value is None else float(value)


def _encode(name: str, **fields: Any) -> bytes:
    store = typestore()
    try:
        return bytes(store.serialize_cdr(store.types[PKG + name](**fields), PKG + name))
    except (TypeError, ValueError, KeyError, OverflowError) as exc:
        raise BagError(f"cannot build {PKG + name} ({exc})") from exc


def encode_model_msg(model: Mapping[str, Any], *, stamp_ns: int, window: tuple[int, int] = (0, 0),
                     frame_id: str = "pmsm") -> bytes:
    """``pmsm_sysid/msg/NarxModel`` CDR bytes from the identify JSON (window in stamp ns)."""
    term_t = typestore().types[PKG + "NarxTerm"]
    try:
        s = model["structure"]
        terms = [term_t(name=str(t["name"]), estimate=float(t["estimate"]),
                        std=_f(t, "std"), err=_f(t, "err")) for t in model["terms"]]
        fields = {"input_name": str(model.get("input", "thrust")),
                  "output_name": str(model["output"]),
                  "sample_rate_hz": float(model["sample_rate_hz"]),
                  "ny": int(s["ny"]), "nu": int(s["nu"]), "degree": int(s["degree"]),
                  "delay": int(s["delay"]), "n_candidates": int(s.get("n_candidates", 0))}
        fit_time_s = _f(model.get("timing_ms", {}), "total") / 1000.0
    except (KeyError, TypeError, ValueError) as exc:
        raise BagError(f"not an identify JSON model ({type(exc).__name__}: {exc})") from exc
    return _encode("NarxModel", header=_header(stamp_ns, frame_id),
                   window_start=_time(window[0]), window_end=_time(window[1]), terms=terms,
                   fit_time_s=fit_time_s, **fields)


def encode_validation_msg(validation: Mapping[str, Any], *, stamp_ns: int,
                          window: tuple[int, int] = (0, 0), frame_id: str = "pmsm") -> bytes:
    """``pmsm_sysid/msg/ValidationStats`` CDR bytes from the identify JSON's ``validation``."""
    test_t = typestore().types[PKG + "CorrelationTest"]
    try:
        est, val = validation["estimation"], validation["validation"]
        corr = validation.get("correlation_tests", {})
        tests: list[Any] = [test_t(name=k, max_abs=_f(corr[k], "max_abs"), band=_f(corr[k], "band"),
                                   passed=bool(corr[k]["pass"]))
                            for k in CORRELATION_TESTS if k in corr]
    except (KeyError, TypeError, ValueError) as exc:
        raise BagError(f"not an identify JSON validation ({type(exc).__name__}: {exc})") from exc
    return _encode("ValidationStats", header=_header(stamp_ns, frame_id),
                   window_start=_time(window[0]), window_end=_time(window[1]),
                   estimation_nmse=_f(est, "nmse"), estimation_r2=_f(est, "r2"),
                   validation_nmse=_f(val, "nmse"), validation_r2=_f(val, "r2"),
                   validation_osa_r2=_f(val, "osa_r2"), correlation_tests=tests,
                   all_passed=bool(tests) and all(t.passed for t in tests))


def encode_ridges_msg(gfrf: Mapping[str, Any], *, stamp_ns: int, window: tuple[int, int] = (0, 0),
                      frame_id: str = "pmsm") -> bytes:
    """``pmsm_sysid/msg/GfrfRidges`` CDR bytes from the gfrf JSON."""
    ridge_t = typestore().types[PKG + "Ridge"]

    def ridges(order: int, items: list[Mapping[str, Any]]) -> list[Any]:
        return [ridge_t(order=order, kind=str(r.get("kind", "f1")), freq_hz=_f(r, "freq_hz"),
                        freq_norm=_f(r, "freq_norm"), gain_db=_f(r, "gain_db")) for r in items]

    try:
        fields = {"h1_peaks": ridges(1, gfrf.get("h1", {}).get("peaks", [])),
                  "h2_ridges": ridges(2, gfrf.get("h2", {}).get("ridges", [])),
                  "h3_ridges": ridges(3, gfrf.get("h3", {}).get("ridges", [])),
                  "sample_rate_hz": float(gfrf["sample_rate_hz"]),
                  "stable": bool(gfrf.get("stable", False))}
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise BagError(f"not a gfrf JSON ({type(exc).__name__}: {exc})") from exc
    return _encode("GfrfRidges", header=_header(stamp_ns, frame_id),
                   window_start=_time(window[0]), window_end=_time(window[1]), **fields)
