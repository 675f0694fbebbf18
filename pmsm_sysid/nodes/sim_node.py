"""MotorSimNode: the simulated linear PMSM on ROS 2.

Per sample k (exactly the order of :func:`pmsm_sysid.core.physics.motor.simulate`, so the numbers
equal the offline simulation of the same plant and seed bit for bit):

1. ``(speed, position) = sim.measure()``  — measured at t_k;
2. ``u = excitation[k]``;
3. publish ``<ns>/thrust`` (WrenchStamped force.x = u; ``<ns>`` is the node's namespace,
   default ``/pmsm``: node ``/pmsm/pmsm_sim``, topic names relative to it), ``<ns>/speed``
   (TwistStamped linear.x), ``<ns>/position`` (PointStamped point.x), all with
   ``header.stamp = t_k``, as serialized messages (:class:`pmsm_sysid.rosutil.SampleEncoder`:
   the same bytes, cheaper to publish);
4. ``sim.advance(u)`` — u held over [t_k, t_{k+1}).

With the sim clock ``/clock`` leads the data: while anyone subscribes to it, ``/clock = t_k``
before each sample; while nobody does, once per :meth:`MotorSimNode.step`, before its first
sample, at the stamp of its last (no sample is ever stamped after the latest ``/clock``).

Clock (parameter ``clock``): ``wall`` stamps t_k = t_0 + k/fs (a drift-free sample clock
started when the first sample is published, however long the node was held before: the
stamps are the wall time of each sample, which a recording of a crash relies on) and paces
samples to real time, catching up in bursts when the timer is late, never
skipping a sample; ``sim`` stamps t_k = k/fs exactly as ``simulate`` does, publishes
``/clock`` and runs at ``rate`` x real time, or with ``rate: 0.0`` as fast as the executor
allows: ``burst`` samples (default 1) per executor round. rclpy's executors take one message
per subscription per round, so one sample per round keeps a subscriber in the same executor
in step (more per round outruns it and its keep-last queue overflows).
:meth:`MotorSimNode.step` publishes n samples at once (for tests and tools that pace
themselves).

Parameters mirror the plant file: the plant's scalars by name, each effect
block as ``<effect>.enabled`` plus ``<effect>.<key>`` (``cogging.harmonics`` is a YAML/JSON
list), and ``excitation``, ``amplitude_n``, ``seed``, ``clock``, ``rate``,
``burst``, ``max_samples``, ``frame_id``. A change at run time rebuilds the plant (validated:
invalid values are rejected with the reason) and calls ``sim.set_plant`` keeping the state.
``sample_rate_hz``, ``seed``, ``clock`` and ``frame_id`` are fixed once running.

Data QoS: reliable; publishers keep the last 10000 samples for a reader that has not
acknowledged them (``PUBLISH_DEPTH``, 20 s at 500 Hz), subscribers the last 1000
(:func:`pmsm_sysid.rosutil.data_qos`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from ..core.errors import ExcitationError, PmsmSysidError
from ..core.physics.excitation import DEFAULT_AMPLITUDE_N, EXCITATIONS, ExcitationSource
from ..core.physics.motor import MotorSimulator
from ..core.physics.plant import EFFECT_BLOCKS, Plant, nominal_plant, plant_from_dict, plant_to_dict
from ..rosutil import SampleEncoder, data_qos, message_class, seconds_to_ns
from ..topics import DEFAULT_NAMESPACE, INPUT_TYPES, POSITION, SPEED, THRUST
from .health import HealthPublisher, sim_health
from .params import apply_or_refuse, declare_all, sim_specs

ParamValue = bool | int | float | str
FIXED = ("sample_rate_hz", "seed", "clock", "frame_id")
_BLOCK = 1000  # excitation samples computed per call
_MAX_CATCH_UP = 50  # samples per timer callback when the timer runs late (paced clocks)


# --- plant <-> flat ROS parameters --------------------------------------------------------

def plant_parameters(plant: Plant) -> dict[str, ParamValue]:
    """Flat parameter map of ``plant``: scalars by name, ``<effect>.enabled|<key>`` per block.

    Keys of a switched-off block take their dataclass default, or 0.0 where the block has no
    default (enable a block together with its values: a zero pitch is rejected).
    """
    out: dict[str, ParamValue] = {}
    given = plant_to_dict(plant)
    for f in fields(Plant):
        if f.name not in EFFECT_BLOCKS:
            out[f.name] = getattr(plant, f.name)
            continue
        block = given.get(f.name)
        out[f"{f.name}.enabled"] = block is not None
        for bf in fields(EFFECT_BLOCKS[f.name]):
            if block is not None:
                value = block[bf.name]
            elif bf.name == "harmonics":
                value = []
            else:
                value = bf.default if isinstance(bf.default, (int, float)) else 0.0
            out[f"{f.name}.{bf.name}"] = json.dumps(value) if bf.name == "harmonics" else value
    return out


def plant_from_parameters(values: Mapping[str, Any]) -> Plant:
    """Inverse of :func:`plant_parameters` (validated by ``plant_from_dict``: PlantError)."""
    import yaml

    from ..core.errors import PlantError

    d: dict[str, Any] = {}
    for f in fields(Plant):
        if f.name not in EFFECT_BLOCKS:
            d[f.name] = values[f.name]
            continue
        if not values[f"{f.name}.enabled"]:
            continue
        block: dict[str, Any] = {}
        for bf in fields(EFFECT_BLOCKS[f.name]):
            value = values[f"{f.name}.{bf.name}"]
            if bf.name == "harmonics":
                try:
                    value = yaml.safe_load(value) or []
                except yaml.YAMLError as exc:
                    raise PlantError(f"cogging.harmonics is not a YAML list: {value!r}") from exc
            block[bf.name] = value
        d[f.name] = block
    return plant_from_dict(d)


# --- the sample stepper (no ROS) ----------------------------------------------------------

class SampleStepper:
    """Simulator + excitation + sample index: yields one sample per :meth:`next`."""

    def __init__(self, plant: Plant, kind: str, seed: int, amplitude_n: float,
                 options: Mapping[str, Any] | None = None) -> None:
        self.sim = MotorSimulator(plant, seed=seed)
        self.seed = seed
        self.options = dict(options or {})
        self.source = ExcitationSource(kind, plant.sample_rate_hz, seed=seed,
                                       amplitude_n=amplitude_n, **self.options)
        self._k0 = 0
        self._u = self.source.block(0, _BLOCK)

    @property
    def k(self) -> int:
        return self.sim.sample_index

    def set_excitation(self, kind: str, amplitude_n: float) -> None:
        """Switch the excitation from the next sample on (the index k continues)."""
        opts = self.options if kind == self.source.kind else {}
        self.source = ExcitationSource(kind, self.sim.plant.sample_rate_hz, seed=self.seed,
                                       amplitude_n=amplitude_n, **opts)
        self._k0 = self.k
        self._u = self.source.block(self._k0, _BLOCK)

    def sample(self) -> tuple[int, float, float, float]:
        """(k, thrust, speed, position) of the current sample k (call :meth:`advance` next)."""
        k = self.k
        if k - self._k0 >= len(self._u):
            self._k0 = k
            self._u = self.source.block(k, _BLOCK)
        speed, position = self.sim.measure()
        return k, float(self._u[k - self._k0]), speed, position

    def advance(self, thrust: float) -> None:
        """Hold ``thrust`` over [t_k, t_{k+1}): the plant moves on to sample k+1."""
        self.sim.advance(thrust)


# --- the node -----------------------------------------------------------------------------

#: samples a publisher keeps for a reader that has not acknowledged them (20 s at 500 Hz):
#: a reliable reader starved of CPU for a while (a recorder on a loaded machine) loses none
PUBLISH_DEPTH = 10000

class MotorSimNode(Node):
    """Publishes the simulated motor's three topics at the plant's sample rate."""

    def __init__(self, *, context: Context | None = None, plant: Plant | None = None,
                 excitation: str = "paper-speed", seed: int = 0,
                 amplitude_n: float | None = None, namespace: str = DEFAULT_NAMESPACE,
                 clock: str = "wall", rate: float = 1.0, burst: int = 1,
                 max_samples: int = 0, frame_id: str = "pmsm",
                 excitation_options: Mapping[str, Any] | None = None,
                 node_name: str = "pmsm_sim",
                 parameter_overrides: list[Parameter] | None = None,
                 cli_args: list[str] | None = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace, cli_args=cli_args,
                         parameter_overrides=parameter_overrides or [])
        try:
            self._wire(plant, excitation, seed, amplitude_n, clock, rate, burst,
                       max_samples, frame_id, excitation_options)
        except BaseException:
            self.destroy_node()  # type: ignore[no-untyped-call]
            raise

    def _wire(self, plant: Plant | None, excitation: str, seed: int, amplitude_n: float | None,
              clock: str, rate: float, burst: int, max_samples: int,
              frame_id: str, excitation_options: Mapping[str, Any] | None) -> None:
        if excitation not in EXCITATIONS:
            raise ExcitationError(f"unknown excitation '{excitation}'; valid: "
                                  f"{', '.join(EXCITATIONS)}")
        defaults: dict[str, ParamValue] = {
            **plant_parameters(plant or nominal_plant()), "excitation": excitation,
            "amplitude_n": float(DEFAULT_AMPLITUDE_N[excitation] if amplitude_n is None
                                 else amplitude_n),
            "seed": int(seed), "clock": clock, "rate": float(rate),
            "burst": int(burst), "max_samples": int(max_samples), "frame_id": frame_id,
        }
        self.values = declare_all(self, defaults, sim_specs(list(defaults)))
        check_run_values(self.values)
        v = self.values
        self.stepper = SampleStepper(plant_from_parameters(v), v["excitation"], v["seed"],
                                     v["amplitude_n"], excitation_options)
        self.fs = self.stepper.sim.plant.sample_rate_hz
        self.published = 0
        self.finished = False
        self._encoder = SampleEncoder(v["frame_id"])  # serialized messages: cheaper
        self._pubs = {sig: self.create_publisher(message_class(t), sig, data_qos(PUBLISH_DEPTH))
                      for sig, t in INPUT_TYPES.items()}
        self._clock_pub = (self.create_publisher(Clock, "/clock", 10)
                           if v["clock"] == "sim" else None)
        self._t0_ns = 0 if v["clock"] == "sim" else time.time_ns()
        self._pace_start = (time.monotonic(), 0)
        self._timer = self.create_timer(self._timer_period(), self._on_timer)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.health = HealthPublisher(self, "sim", sim_health(self))

    @property
    def input_publishers(self) -> list[Any]:
        """The publishers of ``<ns>/thrust``, ``<ns>/speed`` and ``<ns>/position``."""
        return list(self._pubs.values())

    # ------------------------------------------------------------------ stepping
    def stamp_ns(self, k: int) -> int:
        """Header stamp of sample k: k/fs (sim clock) or start time + k/fs (wall clock)."""
        return self._t0_ns + seconds_to_ns(k / self.fs)

    def step(self, n: int = 1) -> int:
        """Publish the next ``n`` samples now (fewer if ``max_samples`` is reached)."""
        limit = self.values["max_samples"]
        if limit:
            n = min(n, limit - self.published)
        n = max(n, 0)
        clock, per_sample = self._clock_pub, False
        if clock is not None and n:
            # /clock per sample for whoever listens to it; else once, first, at the newest
            # stamp of the burst (its samples are never ahead of the clock)
            per_sample = clock.get_subscription_count() > 0
            if not per_sample:
                clock.publish(self._encoder.clock(self.stamp_ns(self.stepper.k + n - 1)))
        # the per-sample calls bound once per burst (most of a sample's 9 us are the three
        # publishes and the plant's RK4 step)
        stepper, encode, stamp_ns = self.stepper, self._encoder.encode, self.stamp_ns
        sample, advance, measured = stepper.sample, stepper.sim.advance, stepper.sim.measured_thrust
        handles = [self._pubs[sig].handle for sig in (THRUST, SPEED, POSITION)]
        with handles[0], handles[1], handles[2]:  # held for the burst, not per message
            thrust, speed, position = (h.publish_raw for h in handles)
            for _ in range(n):
                k, u, v, x = sample()
                stamp = stamp_ns(k)
                if per_sample:
                    clock.publish(self._encoder.clock(stamp))  # type: ignore[union-attr]
                a, b, c = encode(stamp, measured(u), v, x)
                thrust(a)
                speed(b)
                position(c)
                advance(u)
                self.published += 1
        if limit and self.published >= limit:
            self.finished = True
        return n

    def stop_timer(self) -> None:
        """Stop the node's own pacing; the caller then publishes with :meth:`step`."""
        self._timer.cancel()  # type: ignore[no-untyped-call]

    def start_timer(self) -> None:
        """(Re)start the node's own pacing from now (after :meth:`stop_timer`)."""
        self._pace_start = (time.monotonic(), self.published)
        self._timer.reset()  # type: ignore[no-untyped-call]

    def _timer_period(self) -> float:
        """1/fs on the wall clock; rate 0: 0 (one callback per executor round); else
        1/(rate fs), at least 0.5 ms (several samples per callback beyond 2 kHz)."""
        if self.values["clock"] == "wall":
            return 1.0 / self.fs
        rate = self.values["rate"]
        return 0.0 if rate == 0.0 else max(1.0 / (rate * self.fs), 0.0005)

    def _start_wall_clock(self) -> None:
        """Wall clock, before the first sample: stamps and pacing start now."""
        self._t0_ns = time.time_ns()
        self._pace_start = (time.monotonic(), 0)

    def _on_timer(self) -> None:
        if self.finished:
            self._timer.cancel()  # type: ignore[no-untyped-call]
            return
        wall = self.values["clock"] == "wall"
        if wall and self.published == 0:
            self._start_wall_clock()
        rate = 1.0 if wall else self.values["rate"]
        if rate == 0.0:
            self.step(self.values["burst"])
            return
        t_start, k_start = self._pace_start
        due = k_start + math.floor((time.monotonic() - t_start) * self.fs * rate) + 1
        self.step(min(due - self.published, _MAX_CATCH_UP))

    # ------------------------------------------------------------------ parameters
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        return apply_or_refuse(self._apply, params)

    def _apply(self, changes: dict[str, Any]) -> None:
        fixed = [n for n in changes if n in FIXED and changes[n] != self.values[n]]
        if fixed:
            raise PmsmSysidError(f"{', '.join(fixed)} cannot change while the node runs")
        candidate = {**self.values, **changes}
        check_run_values(candidate)
        plant = plant_from_parameters(candidate)
        if any(n in changes for n in ("excitation", "amplitude_n")):
            self.stepper.set_excitation(candidate["excitation"], candidate["amplitude_n"])
        self.stepper.sim.set_plant(plant)
        self.values = candidate
        if "rate" in changes:
            self._pace_start = (time.monotonic(), self.published)
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(self._timer_period(), self._on_timer)
        # max_samples alone is how `run --duration` stops the motor: not the user's change
        said = {k: v for k, v in changes.items() if k != "max_samples"}
        if said:
            self.get_logger().info(  # type: ignore[no-untyped-call]
                f"parameters changed: {', '.join(f'{k}={said[k]}' for k in sorted(said))}; "
                f"effects on: {', '.join(plant.effects) or 'none'}")


def check_run_values(values: Mapping[str, Any]) -> None:
    """Validate the non-plant parameters; PmsmSysidError naming the bad one."""
    if values["clock"] not in ("wall", "sim"):
        raise PmsmSysidError(f"clock must be 'wall' or 'sim', got '{values['clock']}'")
    if values["excitation"] not in EXCITATIONS:
        raise ExcitationError(f"unknown excitation '{values['excitation']}'")
    rate = values["rate"]
    if not (math.isfinite(rate) and rate >= 0):
        raise PmsmSysidError(f"rate must be >= 0 (0 = as fast as possible), got {rate}")
    if values["clock"] == "wall" and rate != 1.0:
        raise PmsmSysidError("rate applies to clock=sim only (the wall clock runs at 1x)")
    if values["burst"] < 1:
        raise PmsmSysidError(f"burst must be >= 1, got {values['burst']}")
    if values["max_samples"] < 0:
        raise PmsmSysidError(
            f"max_samples must be >= 0 (0 = unlimited), got {values['max_samples']}")
    if values["amplitude_n"] < 0 or not math.isfinite(values["amplitude_n"]):
        raise ExcitationError(f"amplitude_n must be a finite number >= 0, got "
                              f"{values['amplitude_n']}")

