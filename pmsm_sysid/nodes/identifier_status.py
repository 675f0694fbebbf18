"""The identifier's diagnostics (``diagnostic_msgs/DiagnosticStatus``): one window's
cross-validation, with the run's windows so far, and a detected plant change."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from ..core.frequency.analysis import json_safe

OK, WARN = DiagnosticStatus.OK, DiagnosticStatus.WARN


def status(name: str, level: bytes, message: str, hardware_id: str,
           values: dict[str, Any]) -> DiagnosticStatus:
    """A DiagnosticStatus with ``values`` as strings (floats with full precision)."""
    return DiagnosticStatus(
        name=name, level=level, message=message, hardware_id=hardware_id,
        values=[KeyValue(key=k, value=v if isinstance(v, str) else json.dumps(json_safe(v)))
                for k, v in values.items()])


def validation_status(v: dict[str, Any], decision: dict[str, Any] | None = None,
                      threshold: float | None = None,
                      count: list[int] | None = None,
                      shift: float | None = None) -> DiagnosticStatus:
    """One window's cross-validation, with the run's windows so far (``count``: passed,
    made; ``shift``: the hop over the window, default the identifier's defaults') judged
    as the run summary judges them (against 1 in 20, allowing for the windows' overlap)."""
    from ..core.validation.windows import DEFAULT_SHIFT, window_rate

    fr = v["free_run"]
    n_est = sum(t["pass"] for t in v["correlation_tests"].values())
    n_new = sum(t["pass"] for t in v["correlation_tests_validation"].values())
    msg = (f"window {'pass' if v['pass'] else 'fail'}: free-run NRMSE {fr['nrmse']:.3g}, "
           f"R2 {fr['r2']:.4g} on the next window; correlation tests {n_est}/5 "
           f"(estimation), {n_new}/5 (next window)")
    values = {"model_id": v["model_id"], "nrmse": fr["nrmse"], "r2": fr["r2"],
              "diverged": fr["diverged"], "osa_r2": v["osa_r2"], "min_r2": v["min_r2"],
              "validated_on": v["validated_on"], "pass": v["pass"]}
    if count:
        rate = window_rate(count[0], count[1], shift=DEFAULT_SHIFT if shift is None else shift)
        values.update(windows_passed=count[0], windows_validated=count[1],
                      run_p_value=rate["p_value"], run_consistent=rate["consistent"])
        msg += (f"; run: {count[0]}/{count[1]} windows passed, "
                + ("as a correct model does (1 in 20 fail by chance)" if rate["consistent"]
                   else f"more failures than chance (p = {rate['p_value']:.2g})"))
    for prefix, key in (("corr", "correlation_tests"),
                        ("corr_next", "correlation_tests_validation")):
        for name, t in v[key].items():
            values[f"{prefix}.{name}"] = {k: t[k] for k in ("max_abs", "band", "pass",
                                                            "n_outside", "n_lags",
                                                            "n_allowed") if k in t}
    if decision is not None:  # the change statistic of this window and its threshold
        values.update(change_score=decision["score"], change_state=decision["state"],
                      change_threshold=threshold)
    return status(f"identifier/cross_validation/{v['output']}", OK if v["pass"] else WARN,
                  msg, v["model_id"], values)


def validation_statuses(validations: Sequence[dict[str, Any]],
                        decisions: Sequence[dict[str, Any]],
                        threshold: float, counts: dict[str, list[int]],
                        grid: dict[str, int]) -> list[DiagnosticStatus]:
    """One window's validations, each with its output's change decision and run count
    (``grid``: the identifier's window and hop)."""
    from ..core.validation.windows import grid_shift

    score = {d["output"]: d for d in decisions}  # the change detector, per output
    shift = grid_shift(grid)
    return [validation_status(v, score.get(v["output"]), threshold, counts.get(v["output"]),
                              shift) for v in validations]


def change_status(c: dict[str, Any]) -> DiagnosticStatus:
    msg = f"plant change on {c['output']}: {', '.join(c['reasons'])}"
    return status(f"identifier/change/{c['output']}", WARN, msg, c["model_id"],
                  {"window": c["window"], "z": c["z"], "values": c["values"],
                   "reasons": c["reasons"]})
