"""The plant file's schema: every key, its type and bounds that mean something physically.

One table (:data:`BOUNDS`) feeds both the JSON Schema that plant files and plant mappings are
validated against (with ``jsonschema``) and the checks a
:class:`~pmsm_sysid.core.physics.plant.Plant` built in Python runs, so a file, a mapping and the
API refuse the same things with the same words: the key (``cogging.harmonics[2].order``) and
what is wrong with its value.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields
from typing import Any

from ..errors import PlantError


@dataclass(frozen=True)
class Bound:
    """``low <= value <= high`` (strict where ``*_open``); ``integer`` for counts."""

    low: float
    high: float
    low_open: bool = False
    high_open: bool = False
    integer: bool = False

    def describe(self) -> str:
        lo = f"> {self.low:g}" if self.low_open else f">= {self.low:g}"
        hi = f"< {self.high:g}" if self.high_open else f"<= {self.high:g}"
        return f"{lo} and {hi}"


_POS = dict(low_open=True)
#: Bounds per key name (SI units). Wide enough for any linear motor axis from a lab stage to
#: a machine-tool axis, tight enough that a typo (a rate of 1e9 Hz, a mass of 1e20 kg) or an
#: effect that could only ever overflow the simulation is refused before anything runs.
BOUNDS: dict[str, Bound] = {
    "mass_kg": Bound(0, 1e4, **_POS),
    "viscous_n_per_mps": Bound(0, 1e6),
    "rs_ohm": Bound(0, 1e4, **_POS),
    "ls_h": Bound(0, 10, **_POS),
    "flux_wb": Bound(0, 1e3, **_POS),
    "sample_rate_hz": Bound(1, 1e5),
    "substeps": Bound(1, 4096, integer=True),
    "amplitude_n": Bound(-1e6, 1e6),
    "pitch_m": Bound(0, 100, **_POS),
    "phase_rad": Bound(-1e3, 1e3),
    "order": Bound(1, 1000, integer=True),
    "smoothing_mps": Bound(0, 100, **_POS),
    "static_n": Bound(0, 1e6),
    "velocity_mps": Bound(0, 100, **_POS),
    "relative": Bound(-1, 1, low_open=True, high_open=True),
    "tau_s": Bound(0, 10),
    "delay_s": Bound(0, 10),
    "stiffness_n_per_m": Bound(0, 1e9),
    "speed_std": Bound(0, 1e3),
    "position_std": Bound(0, 1e3),
    "force_std": Bound(0, 1e6),
    "thrust_std": Bound(0, 1e6),
    "position_m": Bound(0, 1),
    "speed_mps": Bound(0, 100),
}
#: Most cogging harmonics a plant may list.
MAX_HARMONICS = 64
#: Largest plant file read (a plant file is a few hundred bytes).
MAX_FILE_BYTES = 1 << 20


def check_value(where: str, name: str, value: Any) -> None:
    """One number against :data:`BOUNDS` (booleans and strings are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PlantError(f"{where}{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise PlantError(f"{where}{name} must be finite, got {value}")
    b = BOUNDS.get(name)
    if b is None:
        return
    if b.integer and float(value) != int(value):
        raise PlantError(f"{where}{name} must be an integer, got {value}")
    if b.low == 0 and b.low_open and not value > 0:
        raise PlantError(f"{where}{name} must be > 0, got {value}")
    if b.low == 0 and not b.low_open and value < 0:
        raise PlantError(f"{where}{name} must be >= 0, got {value}")
    if b.low == -1 and b.high == 1 and not abs(value) < 1:
        raise PlantError(f"{where}{name} must be between -1 and 1, got {value}")
    low_bad = value <= b.low if b.low_open else value < b.low
    high_bad = value >= b.high if b.high_open else value > b.high
    if low_bad or high_bad:
        raise PlantError(f"{where}{name} must be {b.describe()}, got {value}")


# ----------------------------------------------------------------------------- JSON Schema


def _number(name: str) -> dict[str, Any]:
    b = BOUNDS.get(name)
    out: dict[str, Any] = {"type": "integer" if b is not None and b.integer else "number",
                           "finite": True}
    if b is not None:
        out["exclusiveMinimum" if b.low_open else "minimum"] = b.low
        out["exclusiveMaximum" if b.high_open else "maximum"] = b.high
    return out


def _object(cls: type, *, block: bool, harmonic: type | None = None) -> dict[str, Any]:
    props: dict[str, Any] = {}
    for f in fields(cls):
        if f.name == "harmonics" and harmonic is not None:
            props[f.name] = {"type": "array", "maxItems": MAX_HARMONICS,
                             "items": _object(harmonic, block=False)}
        elif f.name == "tau_s":
            props[f.name] = {"anyOf": [_number(f.name), {"const": "electrical"}]}
        else:
            props[f.name] = _number(f.name)
    if block:
        props["enabled"] = {"type": "boolean"}
    required = [f.name for f in fields(cls)
                if f.default is MISSING and f.default_factory is MISSING]
    return {"type": "object", "properties": props, "additionalProperties": False,
            "required": required}


def plant_schema(plant: type, blocks: Mapping[str, type], harmonic: type) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a plant file, plus the keyword ``finite``: the
    fields of the ``plant`` dataclass, each effect block of ``blocks`` (or null), cogging
    harmonics as ``harmonic`` entries."""
    schema = _object(plant, block=False)
    for name, cls in blocks.items():
        schema["properties"][name] = {"anyOf": [{"type": "null"},
                                                _object(cls, block=True, harmonic=harmonic)]}
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return schema


def _finite(validator: Any, wanted: Any, instance: Any, schema: Any) -> Any:
    from jsonschema.exceptions import ValidationError

    if wanted and isinstance(instance, float) and not math.isfinite(instance):
        yield ValidationError(f"{instance} is not finite")


def plant_validator(schema: dict[str, Any]) -> Any:
    """A jsonschema validator of ``schema`` that knows the keyword ``finite``."""
    from jsonschema import Draft202012Validator, validators

    return validators.extend(Draft202012Validator, {"finite": _finite})(schema)


def _where(path: Any) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _unknown(where: str, keys: list[str], valid: list[str]) -> PlantError:
    parts = []
    for key in keys:
        close = difflib.get_close_matches(str(key), valid, n=1)
        parts.append(f"'{key}'" + (f" (did you mean '{close[0]}'?)" if close else ""))
    return PlantError(f"unknown key{'s' if len(keys) > 1 else ''} {where}{', '.join(parts)}"
                      f"; valid: {', '.join(valid)}")


def _deepest(error: Any) -> Any:
    """For ``anyOf`` (a block or null; a number or 'electrical'), the branch that matters."""
    while error.validator == "anyOf" and error.context:
        inner = [e for e in error.context if not (e.validator == "type" and
                                                   e.validator_value in ("null",))]
        inner = [e for e in inner if e.validator != "const"] or inner
        error = max(inner, key=lambda e: len(e.absolute_path))
    return error


def _message(error: Any) -> PlantError:
    e = _deepest(error)
    key = _where(e.absolute_path)
    name = str(e.absolute_path[-1]) if e.absolute_path else "plant"
    where = key[: len(key) - len(name)] if key.endswith(name) else ""
    value = e.instance
    if e.validator == "additionalProperties":
        valid = sorted(e.schema["properties"])
        extra = [k for k in value if k not in e.schema["properties"]]
        return _unknown(f"in {key}: " if key else "", extra, valid)
    if e.validator == "required":
        missing = [k for k in e.validator_value if k not in value]
        return PlantError(f"{key or 'plant'} is missing {', '.join(missing)}")
    if e.validator == "maxItems":
        return PlantError(f"{key} lists {len(value)} entries, at most {e.validator_value}")
    if e.validator == "type" and e.validator_value == "object":
        return PlantError(f"{key or 'plant'} must be a mapping of keys, got {value!r:.60}")
    if e.validator == "type" and e.validator_value == "array":
        return PlantError(f"{key} must be a list, got {value!r:.60}")
    if e.validator == "type" and e.validator_value == "boolean":
        return PlantError(f"{key} must be true or false, got {value!r:.60}")
    if e.validator == "type" and e.validator_value == "integer" and isinstance(value, float):
        return PlantError(f"{key} must be an integer, got {value}")
    try:
        check_value(where, name, value)
    except PlantError as exc:
        return exc
    return PlantError(f"{key}: {e.message:.120}")  # pragma: no cover - every keyword above


def validate_plant_mapping(d: Any, validator: Any) -> None:
    """Refuse a plant mapping that breaks the schema of ``validator``
    (:func:`plant_validator`), naming the first offending key."""
    if not isinstance(d, Mapping):
        raise PlantError(f"a plant must be a mapping of keys, got {type(d).__name__}")
    from jsonschema.exceptions import best_match

    error = best_match(validator.iter_errors(d),
                       key=lambda e: (-len(e.absolute_path), e.validator != "anyOf"))
    if error is not None:
        raise _message(error)


# ----------------------------------------------------------------------------- YAML


_FLOAT = re.compile(r"^[-+]?(?:\d[\d_]*(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?$")


def yaml_loader() -> Any:
    """A safe YAML loader that reads ``4e-3`` as a number (YAML 1.2), as a reader expects;
    PyYAML alone reads it as the string '4e-3'."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.yaml_implicit_resolvers = {k: list(v) for k, v in
                                      yaml.SafeLoader.yaml_implicit_resolvers.items()}
    Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))
    return Loader
