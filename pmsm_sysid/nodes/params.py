"""Parameter descriptors of the package's nodes, and the identifier's live settings.

Every node parameter is declared with a ``ParameterDescriptor``: a description (what it is,
its unit), its type (fixed: a value of another type is refused), a range where one applies
(rclpy refuses values outside it with the reason), and ``read_only`` for what cannot change
while the node runs. ``ros2 param describe /pmsm/pmsm_identifier hop`` shows it.

The identifier applies a change of its fit settings (``window``, ``hop``, structure,
``terms``, ``method``, ``criterion``, ``outputs``, ``min_r2``, ``change.*``) from the next
window on: :class:`SwitchableProcessor` hands the first window cut with the new settings to
a fresh tracker (the running fit finishes as it started). The fresh tracker starts its
cross-validation and change baselines anew: models of different settings are not compared.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, wait
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node

from ..core.errors import DataError, PmsmSysidError
from ..core.online.fitqueue import Ticket

W = TypeVar("W")
R = TypeVar("R")
BIG = 1_000_000


@dataclass(frozen=True)
class Spec:
    """What a parameter is (``text``), its range (inclusive) and whether it is fixed."""

    text: str
    low: float | None = None
    high: float | None = None
    read_only: bool = False


def _type(value: Any) -> int:
    if isinstance(value, bool):
        return int(ParameterType.PARAMETER_BOOL)
    if isinstance(value, int):
        return int(ParameterType.PARAMETER_INTEGER)
    if isinstance(value, float):
        return int(ParameterType.PARAMETER_DOUBLE)
    if isinstance(value, str):
        return int(ParameterType.PARAMETER_STRING)
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, str) for v in value):
        return int(ParameterType.PARAMETER_STRING_ARRAY)
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, int) for v in value):
        return int(ParameterType.PARAMETER_INTEGER_ARRAY)
    raise PmsmSysidError(f"no parameter type for default {value!r}")


def descriptor(name: str, default: Any, spec: Spec) -> ParameterDescriptor:
    """The ParameterDescriptor of one parameter (type from its default)."""
    d = ParameterDescriptor(name=name, type=_type(default), description=spec.text,
                            read_only=spec.read_only)
    if spec.low is not None and spec.high is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                            step=1)]
        elif isinstance(default, float):
            d.floating_point_range = [FloatingPointRange(
                from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    return d


def declare_all(node: Node, defaults: Mapping[str, Any],
                specs: Mapping[str, Spec]) -> dict[str, Any]:
    """Declare every parameter of ``defaults`` with its descriptor; the values in effect."""
    from rclpy.exceptions import ParameterException

    out = {}
    for name, default in defaults.items():
        spec = specs.get(name) or Spec(name.replace("_", " ").replace(".", ": "))
        try:
            out[name] = node.declare_parameter(name, default,
                                               descriptor(name, default, spec)).value
        except ParameterException as exc:  # a given value of the wrong type or out of range
            reason = str(exc).split("Reason: ")[-1].strip().removesuffix(f": {name}")
            raise DataError(f"parameter {name}: {reason}") from exc
    return out


# --- the identifier ------------------------------------------------------------------------

def _output_specs(o: str) -> dict[str, Spec]:
    return {
        f"{o}.ny": Spec(f"output lags ny of the {o} model (y(k-1) .. y(k-ny))", 0, 500),
        f"{o}.nu": Spec(f"input lags nu of the {o} model (u(k-d) .. u(k-d-nu+1))", 0, 500),
        f"{o}.degree": Spec(f"polynomial degree of the {o} model's candidate terms", 1, 3),
        f"{o}.delay": Spec(f"input delay d of the {o} model in samples", 1, 100),
        f"{o}.terms": Spec(f"terms the {o} model may select (the constant not counted)",
                           1, 1000),
        f"{o}.form": Spec(f"'level': the {o} as measured; 'difference': its increment per "
                          f"sample (bounded free run of an integrating output)"),
    }


IDENTIFIER_SPECS: dict[str, Spec] = {
    "input_layout": Spec("where samples come from: 'topics' (<ns>/thrust, speed, position) "
                         "or 'joint_state' (one sensor_msgs/JointState topic)", read_only=True),
    "joint_name": Spec("joint_state layout: the joint whose effort, velocity and position are "
                       "thrust (N), speed (m/s) and position (m)", read_only=True),
    "joint_state_topic": Spec("joint_state layout: the JointState topic (default "
                              "/joint_states, where ros2_control's joint_state_broadcaster "
                              "publishes; a relative name is in the node's namespace)",
                              read_only=True),
    "window": Spec("samples per fitted window (from the next window on)", 2, BIG),
    "hop": Spec("samples between two fits: a window is cut every hop samples "
                "(at most window)", 1, BIG),
    "queue_size": Spec("windows that may wait for the fitting thread; when full the oldest "
                       "is skipped (latest wins)", 1, 1000, read_only=True),
    "sample_rate_hz": Spec("sample rate in Hz; 0 = read from the stamps", 0.0, 1e6,
                           read_only=True),
    "tolerance_s": Spec("stamp alignment tolerance in s; 0 = half a sample period", 0.0, 10.0,
                        read_only=True),
    "outputs": Spec("identified outputs: 'speed' and/or 'position'"),
    "method": Spec("term selection: 'ofr' (forward regression) or 'iofr' (iterative OFR)"),
    "criterion": Spec("model size: 'terms' (the given number), 'err' (error reduction "
                      "threshold), 'aic' or 'bic' (at most the given number)"),
    **_output_specs("speed"), **_output_specs("position"),
    "min_r2": Spec("cross-validation passes when the free-run R2 on the next window is at "
                   "least this", 0.0, 1.0),
    "change.s_confirm": Spec("combined change score S that, reached on two consecutive "
                             "windows, reports a plant change", 0.01, 1000.0),
    "change.baseline": Spec("windows in the change detector's running baseline", 3, 100000),
    "change.warmup": Spec("windows the change detector learns before it judges "
                          "(at most change.baseline)", 3, 100000),
    "change.min_r2": Spec("an output is watched for changes while the median free-run R2 of "
                          "its recent windows is at least this", 0.0, 1.0),
    "publish_period_s": Spec("period in s of the timer that publishes finished results",
                             0.001, 10.0, read_only=True),
    "stale_after_s": Spec("seconds without input after which the input is reported stale",
                          0.01, 3600.0),
    "speed_source": Spec("speed input: 'measured' (<ns>/speed), 'derived' (from position by "
                         "a backward difference) or 'auto' (measured when it arrives)",
                         read_only=True),
    "inputs_report_s": Spec("seconds after the start at which the node logs which inputs "
                            "arrived", 0.0, 3600.0),
    "fit_worker": Spec("where fits run: 'process' (a worker process of its own) or 'thread' "
                       "(a thread of this process)", read_only=True),
}

#: identifier parameters whose change needs a new tracker (and maybe a new window ring)
TRACKER_KEYS = frozenset(k for k in IDENTIFIER_SPECS if k.startswith(
    ("speed.", "position.", "change."))) | {"window", "hop", "outputs", "method", "criterion",
                                           "min_r2"}


def check_identifier(values: Mapping[str, Any]) -> None:
    """Consistency of the identifier's settings beyond each parameter's own range."""
    if int(values["hop"]) > int(values["window"]):
        raise DataError(f"hop ({values['hop']}) must be at most window ({values['window']}): "
                        "samples between windows would never be fitted")
    if int(values["change.warmup"]) > int(values["change.baseline"]):
        raise DataError(f"change.warmup ({values['change.warmup']}) must be at most "
                        f"change.baseline ({values['change.baseline']})")


class SwitchableProcessor(Generic[W, R]):
    """``process(window)`` that can be replaced between windows (see the module doc).

    ``switch(new, shape)``: windows whose ``shape_of(window)`` equals ``shape`` go to ``new``
    from then on (the old processor is closed, if it has ``close``); windows cut before the
    change still go to the old one. ``on_take`` (if set) is called as each window is taken,
    in the fitting thread (e.g. to wake an executor waiting for the queue to empty).
    :meth:`submit` hands a window over without waiting (see :class:`.fitqueue.FitWorker`'s
    ``ahead``); a processor switched out first finishes the windows it was given.
    """

    def __init__(self, process: Callable[[W], R], shape_of: Callable[[W], Any]) -> None:
        self._current = process
        self._pending: tuple[Callable[[W], R], Any] | None = None
        self._shape_of = shape_of
        self._lock = threading.Lock()
        self._retired: list[Callable[[W], R]] = []  # closed processors (their CPU counts)
        self.switches = 0
        self.on_take: Callable[[], None] | None = None
        self._handed_over: Future[Any] | None = None  # the newest item submitted

    @property
    def cpu_s(self) -> float:
        """CPU seconds spent in worker processes (0 for in-thread processing)."""
        return sum(float(getattr(p, "cpu_s", 0.0)) for p in (*self._retired, self._current))

    def switch(self, process: Callable[[W], R], shape: Any) -> None:
        with self._lock:
            old, self._pending = self._pending, (process, shape)
        if old is not None:
            _close(old[0])

    def __call__(self, window: W) -> R:
        return self._take(window)(window)

    def submit(self, window: W) -> Ticket:
        """Hand ``window`` over without waiting for its result when the processor that
        takes it computes elsewhere (``submit``); else process it now."""
        process = self._take(window)
        submit = getattr(process, "submit", None)
        if submit is not None:
            ticket: Ticket = submit(window)
            self._handed_over = ticket.future
            return ticket
        done: Future[R] = Future()
        try:
            done.set_result(process(window))
        except Exception as exc:  # delivered by collect(), as a worker's error would be
            done.set_exception(exc)
        return Ticket(done, done.result)

    def _take(self, window: W) -> Callable[[W], R]:
        """The processor for ``window`` (switching over here when it is due)."""
        if self.on_take is not None:
            self.on_take()
        with self._lock:
            if self._pending is not None and self._shape_of(window) == self._pending[1]:
                if self._handed_over is not None:  # the old one finishes what it was given
                    wait([self._handed_over])
                old, self._current = self._current, self._pending[0]
                self._pending = None
                self.switches += 1
                self._retired.append(old)
                _close(old)
            return self._current

    def close(self) -> None:
        with self._lock:
            pending, self._pending = self._pending, None
        _close(self._current)
        if pending is not None:
            _close(pending[0])


def _close(process: Any) -> None:
    close = getattr(process, "close", None)
    if callable(close):
        close()


# --- the sim motor and the GFRF node -------------------------------------------------------

_UNITS = (("speed_std", "m/s"), ("position_std", "m"), ("force_std", "N"), ("thrust_std", "N"),
          ("_n_per_mps", "N/(m/s)"), ("_n_per_m", "N/m"), ("_mps", "m/s"), ("_kg", "kg"),
          ("_ohm", "ohm"), ("_wb", "Wb"), ("_hz", "Hz"), ("_rad", "rad"), ("_n", "N"),
          ("_m", "m"), ("_s", "s"), ("_h", "H"))
SIM_TEXT = {
    "excitation": "thrust excitation: paper-speed, paper-position, multisine, chirp, prbs, "
                  "aprbs (from the next sample on)",
    "amplitude_n": "thrust amplitude in N",
    "seed": "seed of the noise and the excitation",
    "clock": "'wall' (real time, wall-clock stamps) or 'sim' (stamps k/fs, /clock published)",
    "rate": "with clock 'sim': x real time (0 = as fast as the executor allows)",
    "burst": "with rate 0: samples per executor round",
    "max_samples": "stop after this many samples (0 = never)",
    "frame_id": "header.frame_id of the published messages",
    "sample_rate_hz": "sample rate of the simulated drive in Hz",
    "substeps": "plant: integration substeps per sample",
    "mass_kg": "plant: moving mass in kg",
    "viscous_n_per_mps": "plant: viscous friction coefficient in N/(m/s)",
    "rs_ohm": "plant: stator phase resistance Rs in ohm",
    "ls_h": "plant: stator phase inductance Ls in H",
    "flux_wb": "plant: permanent-magnet flux linkage in Wb",
    "relative": "relative amplitude (fraction of the thrust)",
    "harmonics": "cogging harmonics as a YAML/JSON list of {order, amplitude_n, phase_rad}",
}
SIM_FIXED = ("sample_rate_hz", "seed", "clock", "frame_id")


def _words(name: str) -> str:
    """``pitch_m`` -> "pitch in m", ``speed_std`` -> "speed std in m/s"."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            stem = name if suffix.endswith("_std") else name[: -len(suffix)]
            return f"{stem.replace('_', ' ')} in {unit}"
    return name.replace("_", " ")


def sim_specs(names: Sequence[str]) -> dict[str, Spec]:
    """Descriptions of the sim node's parameters (plant values as in the plant file)."""
    out = {}
    for name in names:
        block, _, key = name.rpartition(".")
        if not block:
            text = SIM_TEXT.get(name) or f"plant: {_words(name)} (validated as in a plant file)"
        elif key == "enabled":
            text = f"plant: switch the {block.replace('_', ' ')} effect on (set its values first)"
        else:
            what = SIM_TEXT[key] if key in ("harmonics", "relative") else _words(key)
            text = f"plant: {block.replace('_', ' ')} {what} (validated as in a plant file)"
        out[name] = Spec(text, read_only=name in SIM_FIXED)
    return out


GFRF_SPECS: dict[str, Spec] = {
    "queue_size": Spec("models that may wait for analysis; when full the oldest is skipped",
                       1, 1000, read_only=True),
    "orders": Spec("GFRF orders analysed: any of 1, 2, 3", read_only=True),
    "worker": Spec("where analyses run: 'process' (a worker process of its own) or 'thread'",
                   read_only=True),
    "publish_period_s": Spec("period in s of the timer that publishes finished results",
                             0.001, 10.0, read_only=True),
}


DIAGNOSE_SPECS: dict[str, Spec] = {
    "plant_file": Spec("plant file (YAML) the drive is diagnosed against, or the name of a "
                       "packaged one (drive, nominal, ...); empty with sim_namespace",
                       read_only=True),
    "sim_namespace": Spec("namespace of a simulator publishing its own thrust, speed and "
                          "position beside the drive: the drive is diagnosed against "
                          "recordings of it (instead of a plant file)", read_only=True),
    "period_s": Spec("seconds of data between two diagnoses (stamp time: simulated seconds "
                     "under a simulated clock)", 0.1, 86400.0),
    "span_s": Spec("seconds of the latest inputs each diagnosis looks at; diagnose holds "
                   "out the last 30 % of them to confirm what it names", 1.0, 3600.0),
    "alpha": Spec("family-wise false-alarm level of each step that names an effect",
                  1e-12, 0.5),
    "min_share": Spec("smallest share of the mismatch an effect must explain to be named",
                      0.0, 1.0),
    "replay": Spec("also compare the speed replayed over short horizons, before and after"),
    "gfrf": Spec("also compare the GFRFs of NARX models of the drive and a noisy simulated "
                 "twin (costs about a third more CPU per diagnosis)"),
    "queue_size": Spec("spans that may wait for the worker; when full the oldest is skipped "
                       "(latest wins)", 1, 100, read_only=True),
    "sample_rate_hz": Spec("sample rate in Hz; 0 = read from the stamps", 0.0, 1e6,
                           read_only=True),
    "tolerance_s": Spec("stamp alignment tolerance in s; 0 = half a sample period", 0.0, 10.0,
                        read_only=True),
    "speed_source": Spec("speed input: 'measured', 'derived' (from position by a backward "
                         "difference) or 'auto' (measured when it arrives)", read_only=True),
    "publish_period_s": Spec("period in s of the timer that publishes finished diagnoses",
                             0.001, 10.0, read_only=True),
    "worker": Spec("where diagnoses run: 'process' (a worker process of its own) or "
                   "'thread' (a thread of this process)", read_only=True),
}


def check_orders(orders: Sequence[int]) -> tuple[int, ...]:
    """The GFRF orders as a tuple; DataError unless a non-empty choice among 1, 2, 3."""
    out = tuple(int(o) for o in orders)
    if not out or any(o not in (1, 2, 3) for o in out):
        raise DataError(f"parameter orders must be among 1, 2, 3 (got {list(out)})")
    return out


def apply_or_refuse(apply: Callable[[dict[str, Any]], None],
                    params: Sequence[Any]) -> Any:
    """An on-set-parameters answer: ``apply`` the change as a whole, or refuse it with the
    reason a :class:`PmsmSysidError` gives."""
    from rcl_interfaces.msg import SetParametersResult

    try:
        apply({p.name: p.value for p in params})
    except PmsmSysidError as exc:
        return SetParametersResult(successful=False, reason=str(exc))
    return SetParametersResult(successful=True)
