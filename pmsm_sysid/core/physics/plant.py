"""Plant parameters of the linear PMSM axis and its optional non-ideal effects.

A plant file is YAML whose keys are the field names below (SI units). The nominal plant is
the paper's Table 1 with every effect off. Each effect block is a frozen dataclass whose field
names are the parameter names ``diagnose`` reports. Sign conventions: the
mechanical equation is ``M dv/dt = F_applied - B v - F_effects(x, v, F_applied)`` (see
:func:`pmsm_sysid.core.physics.motor.effects_force`); a block is switched off by leaving it out,
writing ``null``, or ``enabled: false``.
"""

from __future__ import annotations

import importlib.resources
import typing
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

from ..errors import PlantError
from .plant_schema import (
    MAX_FILE_BYTES,
    _unknown,
    check_value,
    plant_schema,
    plant_validator,
    validate_plant_mapping,
    yaml_loader,
)

#: Default velocity scale of the sign(v) regularisation, tanh(v / smoothing_mps).
SIGN_SMOOTHING_MPS = 1e-3


@dataclass(frozen=True)
class Harmonic:
    """One higher cogging harmonic: ``amplitude_n * sin(2*pi*order*x/pitch + phase_rad)``."""

    order: int
    amplitude_n: float
    phase_rad: float = 0.0


@dataclass(frozen=True)
class Cogging:
    """Position-periodic force ``A sin(2 pi x/pitch + phase) + sum of harmonics`` (N)."""

    amplitude_n: float
    pitch_m: float
    phase_rad: float = 0.0
    harmonics: tuple[Harmonic, ...] = ()


@dataclass(frozen=True)
class CoulombFriction:
    """Coulomb friction ``amplitude_n * sign(v)``; sign(v) = tanh(v / smoothing_mps)."""

    amplitude_n: float
    smoothing_mps: float = SIGN_SMOOTHING_MPS


@dataclass(frozen=True)
class StribeckFriction:
    """Stribeck hump ``static_n * exp(-(v/velocity_mps)^2) * sign(v)``.

    ``static_n`` is the friction at standstill *above* any Coulomb level, so the breakaway
    force with both blocks on is ``coulomb.amplitude_n + static_n``.
    """

    static_n: float
    velocity_mps: float
    smoothing_mps: float = SIGN_SMOOTHING_MPS


@dataclass(frozen=True)
class ForceOffset:
    """Constant force in the inverse-dynamics convention ``F = M a + B v + ... + amplitude_n``."""

    amplitude_n: float


@dataclass(frozen=True)
class ThrustRipple:
    """Position-periodic thrust gain: force times ``1 + relative*sin(2 pi x/pitch + phase)``."""

    relative: float
    pitch_m: float
    phase_rad: float = 0.0


@dataclass(frozen=True)
class ThrustLag:
    """First-order lag ``tau_s dF/dt = F_cmd - F`` between the command and the force.

    In a plant file ``tau_s: electrical`` means the winding time constant ``ls_h / rs_ohm``.
    """

    tau_s: float


@dataclass(frozen=True)
class TransportDelay:
    """The command takes effect ``delay_s`` later (any non-negative delay, exactly)."""

    delay_s: float


@dataclass(frozen=True)
class Spring:
    """Restoring force ``stiffness_n_per_m * x`` about x = 0 (cable carrier, position loop)."""

    stiffness_n_per_m: float


@dataclass(frozen=True)
class Noise:
    """White Gaussian noise. Measurement: ``speed_std`` (m/s), ``position_std`` (m).

    ``force_std`` (N) is a process disturbance force, drawn once per sample and held over the
    sample period. ``thrust_std`` (N) is thrust *sensor* noise: the recorded thrust is the
    applied command plus this noise (errors in the input variable, as with a current-sensor
    based thrust reading). The simulator's seed drives all draws.
    """

    speed_std: float = 0.0
    position_std: float = 0.0
    force_std: float = 0.0
    thrust_std: float = 0.0


@dataclass(frozen=True)
class Quantisation:
    """Measurement resolution: readings are rounded to multiples of these steps (0 = off)."""

    position_m: float = 0.0
    speed_mps: float = 0.0


@dataclass(frozen=True)
class Plant:
    """The linear PMSM of the paper's Table 1 (SI units) plus optional effect blocks.

    A frozen dataclass: change a field with :func:`dataclasses.replace`, switch effects on
    with :meth:`with_effects`.

    Example:
        >>> import pmsm_sysid as ps
        >>> ps.Plant.nominal().mass_kg
        2.3213
        >>> ps.Plant.from_yaml("plants/coulomb.yaml").effects
        ('coulomb_friction', 'noise')
    """

    mass_kg: float = 2.3213
    viscous_n_per_mps: float = 32.4992
    rs_ohm: float = 3.8835  # Table 1: 11.6504/3
    ls_h: float = 0.0016  # Table 1: 0.0048/3
    flux_wb: float = 0.4849
    sample_rate_hz: float = 500.0
    substeps: int = 8
    cogging: Cogging | None = None
    coulomb_friction: CoulombFriction | None = None
    stribeck_friction: StribeckFriction | None = None
    force_offset: ForceOffset | None = None
    thrust_ripple: ThrustRipple | None = None
    thrust_lag: ThrustLag | None = None
    transport_delay: TransportDelay | None = None
    spring: Spring | None = None
    noise: Noise | None = None
    quantisation: Quantisation | None = None

    def __post_init__(self) -> None:
        _check_plant(self)

    @property
    def sample_period_s(self) -> float:
        return 1.0 / self.sample_rate_hz

    @property
    def electrical_tau_s(self) -> float:
        """Winding time constant L/R (s): about 0.41 ms for Table 1."""
        return self.ls_h / self.rs_ohm

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the effect blocks that are switched on."""
        return tuple(name for name in EFFECT_BLOCKS if getattr(self, name) is not None)

    def with_effects(self, **blocks: Any) -> Plant:
        """A copy with effect blocks replaced (``None`` switches one off)."""
        return replace(self, **blocks)

    @classmethod
    def nominal(cls) -> Plant:
        """The paper's Table 1 motor with every effect off (same as ``Plant()``)."""
        return nominal_plant()

    @classmethod
    def from_yaml(cls, path: str | Path) -> Plant:
        """Read and check a YAML plant file (``plants/all_effects.yaml`` documents the keys)."""
        return load_plant(path)

    def to_yaml(self) -> str:
        """The plant-file YAML text of this plant."""
        return dump_plant(self)


EFFECT_BLOCKS: dict[str, type] = {
    "cogging": Cogging,
    "coulomb_friction": CoulombFriction,
    "stribeck_friction": StribeckFriction,
    "force_offset": ForceOffset,
    "thrust_ripple": ThrustRipple,
    "thrust_lag": ThrustLag,
    "transport_delay": TransportDelay,
    "spring": Spring,
    "noise": Noise,
    "quantisation": Quantisation,
}

def _check_value(where: str, name: str, value: Any) -> None:
    check_value(where, name, value)


def _check_block(where: str, block: Any) -> None:
    for f in fields(block):
        value = getattr(block, f.name)
        if f.name == "harmonics":
            for i, h in enumerate(value):
                if not isinstance(h, Harmonic):
                    raise PlantError(f"{where}harmonics[{i}] must be a Harmonic, got {h!r}")
                _check_block(f"{where}harmonics[{i}].", h)
        else:
            _check_value(where, f.name, value)
    if isinstance(block, Harmonic) and not isinstance(block.order, int):
        raise PlantError(f"{where}order must be an integer, got {block.order!r}")


def _check_plant(p: Plant) -> None:
    for f in fields(p):
        value = getattr(p, f.name)
        if f.name in EFFECT_BLOCKS:
            if value is not None:
                if not isinstance(value, EFFECT_BLOCKS[f.name]):
                    raise PlantError(f"{f.name} must be a {EFFECT_BLOCKS[f.name].__name__} block")
                _check_block(f"{f.name}.", value)
        else:
            _check_value("", f.name, value)
    if not isinstance(p.substeps, int):
        raise PlantError(f"substeps must be an integer, got {p.substeps!r}")


def nominal_plant() -> Plant:
    """The paper's Table 1 motor with every effect off, sampled at 500 Hz."""
    return Plant()


def electrical_lag(plant: Plant) -> ThrustLag:
    """A thrust lag with the winding time constant ``ls_h / rs_ohm``."""
    return ThrustLag(tau_s=plant.electrical_tau_s)


# ----------------------------------------------------------------------------- dict / YAML


def _coerce(where: str, name: str, value: Any, want: Any) -> Any:
    """Convert one validated value to the field's type (a string is never a number)."""
    _check_value(where, name, value)
    if want is int:
        if float(value) != int(value):
            raise PlantError(f"{where}{name} must be an integer, got {value}")
        return int(value)
    return float(value)


def _build(cls: Any, data: Any, where: str, context: Mapping[str, Any]) -> Any:
    if not isinstance(data, Mapping):
        raise PlantError(f"{where.rstrip('.') or 'plant'} must be a mapping of keys, got {data!r}")
    hints = typing.get_type_hints(cls)
    valid = [f.name for f in fields(cls)]
    extra = [k for k in data if k not in valid and not (k == "enabled" and cls is not Plant)]
    if extra:
        raise _unknown(f"in {where.rstrip('.')}: " if where else "", extra, valid)
    missing = [f.name for f in fields(cls) if f.name not in data
               and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise PlantError(f"{where.rstrip('.')} is missing {', '.join(missing)}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        if name == "enabled":
            continue
        want = hints[name]
        if name == "harmonics":
            if not isinstance(value, list):
                raise PlantError(f"{where}harmonics must be a list, got {value!r}")
            kwargs[name] = tuple(_build(Harmonic, h, f"{where}harmonics[{i}].", context)
                                 for i, h in enumerate(value))
        elif name == "tau_s" and value == "electrical":
            kwargs[name] = context["ls_h"] / context["rs_ohm"]
        elif cls is Plant and name in EFFECT_BLOCKS:
            kwargs[name] = _block_from(name, value, context)
        else:
            kwargs[name] = _coerce(where, name, value, want)
    return cls(**kwargs)


def _block_from(name: str, value: Any, context: Mapping[str, Any]) -> Any:
    if value is None:
        return None
    if isinstance(value, Mapping) and "enabled" in value:
        if not isinstance(value["enabled"], bool):
            raise PlantError(f"{name}.enabled must be true or false, got {value['enabled']!r}")
        if not value["enabled"]:
            return None
    return _build(EFFECT_BLOCKS[name], value, f"{name}.", context)


_VALIDATOR: Any = None


def _validator() -> Any:
    """The plant file's schema validator, built on first use (jsonschema loads lazily)."""
    global _VALIDATOR
    if _VALIDATOR is None:
        _VALIDATOR = plant_validator(plant_schema(Plant, EFFECT_BLOCKS, Harmonic))
    return _VALIDATOR


def plant_from_dict(d: Mapping[str, Any]) -> Plant:
    """Build and validate a :class:`Plant` from a plant-file mapping (missing keys = nominal)."""
    validate_plant_mapping(d, _validator())  # every key, type and bound, before anything else
    nominal = Plant()
    context = {"ls_h": d.get("ls_h", nominal.ls_h), "rs_ohm": d.get("rs_ohm", nominal.rs_ohm)}
    for key in ("ls_h", "rs_ohm"):
        context[key] = _coerce("", key, context[key], float)
    try:
        plant: Plant = _build(Plant, d, "", context)
    except TypeError as exc:  # pragma: no cover - guarded by the checks above
        raise PlantError(f"invalid plant: {exc}") from exc
    return plant


def _to_plain(value: Any) -> Any:
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: _to_plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, tuple):
        return [_to_plain(v) for v in value]
    return value


def plant_to_dict(p: Plant) -> dict[str, Any]:
    """Plain mapping of ``p`` (plant-file layout) that omits switched-off effects."""
    out: dict[str, Any] = {}
    for f in fields(p):
        value = getattr(p, f.name)
        if value is not None:
            out[f.name] = _to_plain(value)
    return out


def packaged_plant_path(name: str) -> Path:
    """Path of a plant file shipped in the package (``nominal`` = Table 1, effects off)."""
    return Path(str(importlib.resources.files("pmsm_sysid") / "data" / f"{name}.yaml"))


def load_plant(path: str | Path) -> Plant:
    """Read and validate a YAML plant file; any problem is one :class:`PlantError` line.

    A bare name without a file of that name (``nominal``) means the packaged plant file.
    """
    import yaml

    p = Path(path)
    if not p.exists() and p.suffix == "" and p.parent == Path("."):
        packaged = packaged_plant_path(p.name)
        p = packaged if packaged.is_file() else p
    try:
        if p.is_file() and p.stat().st_size > MAX_FILE_BYTES:
            raise PlantError(f"{p}: {p.stat().st_size} bytes, too large for a plant file")
        text = p.read_text()
    except FileNotFoundError as exc:
        raise PlantError(f"{p}: no such plant file") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise PlantError(f"{p}: cannot read plant file ({exc.__class__.__name__})") from exc
    try:
        data = yaml.load(text, Loader=yaml_loader())  # a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise PlantError(f"{p}: not valid YAML{at}") from exc
    except RecursionError as exc:
        raise PlantError(f"{p}: YAML nested too deeply for a plant file") from exc
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise PlantError(f"{p}: a plant file must be a YAML mapping of keys, got "
                         f"{type(data).__name__}")
    try:
        return plant_from_dict(data)
    except PlantError as exc:
        raise PlantError(f"{p}: {exc}") from exc


def dump_plant(p: Plant) -> str:
    """YAML text of ``p`` (the plant-file layout), for meta data and ``--plant`` files."""
    import yaml

    text: str = yaml.safe_dump(plant_to_dict(p), sort_keys=False)
    return text

