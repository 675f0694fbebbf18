"""Polynomial NARX terms and identified models (Eqs. 3 and 5 of Liu et al. 2005).

A term is a product of lagged outputs y(k-i) and inputs u(k-j); the empty product is the
constant. Names follow the paper's tables: ``y(k-1)``, ``u(k-10)``, ``y(k-1)u(k-10)``,
``y(k-10)^2``, ``const``. Lags are absolute (the input delay d is already included).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import IdentificationError

FloatArray = NDArray[np.float64]
Factor = tuple[str, int]

_FACTOR_RE = re.compile(r"([yu])\(k-(\d+)\)(?:\^(\d+))?")


def _number(value: Any, what: str, missing_ok: bool = False) -> float:
    """A JSON number (``true`` or ``"0.5"`` are not; null is NaN where ``missing_ok``)."""
    if value is None and missing_ok:
        return float("nan")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise IdentificationError(f"{what} must be a number, got {_shown(value)}")
    return float(value)


def _shown(value: Any) -> str:
    """``value`` as JSON writes it (true, "0.5", null), else its repr."""
    try:
        return json.dumps(value)
    except (TypeError, ValueError):
        return repr(value)


def _integer(value: Any, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise IdentificationError(f"{what} must be a whole number, got {_shown(value)}")
    return value


@dataclass(frozen=True, order=True)
class Term:
    """A monomial of lagged signals, canonical order: y factors by lag, then u factors by lag."""

    factors: tuple[Factor, ...] = ()

    def __post_init__(self) -> None:
        for var, lag in self.factors:
            if var not in ("y", "u") or lag < 1:
                raise IdentificationError(f"bad term factor {var}(k-{lag}): need y or u, lag >= 1")
        canon = tuple(sorted(self.factors, key=lambda f: (f[0] != "y", f[1])))
        object.__setattr__(self, "factors", canon)

    @property
    def degree(self) -> int:
        return len(self.factors)

    @property
    def is_constant(self) -> bool:
        return not self.factors

    @property
    def y_lags(self) -> tuple[int, ...]:
        return tuple(lag for var, lag in self.factors if var == "y")

    @property
    def u_lags(self) -> tuple[int, ...]:
        return tuple(lag for var, lag in self.factors if var == "u")

    @property
    def name(self) -> str:
        if not self.factors:
            return "const"
        parts: list[str] = []
        i = 0
        while i < len(self.factors):
            j = i
            while j < len(self.factors) and self.factors[j] == self.factors[i]:
                j += 1
            var, lag = self.factors[i]
            power = j - i
            parts.append(f"{var}(k-{lag})" + (f"^{power}" if power > 1 else ""))
            i = j
        return "".join(parts)

    def __str__(self) -> str:
        return self.name

    @classmethod
    def parse(cls, name: str) -> Term:
        """Parse a paper-style name; ``y(k-3)y(k-3)`` and ``y(k-3)^2`` are the same term."""
        text = name.replace(" ", "")
        if text in ("const", "constant", "1"):
            return cls(())
        factors: list[Factor] = []
        pos = 0
        for m in _FACTOR_RE.finditer(text):
            if m.start() != pos:
                break
            factors.extend([(m.group(1), int(m.group(2)))] * int(m.group(3) or 1))
            pos = m.end()
        if pos != len(text) or not factors:
            raise IdentificationError(f"cannot parse term name '{name}'")
        return cls(tuple(factors))


@dataclass(frozen=True)
class Structure:
    """Candidate structure: max output lag ny, input lags delay..delay+nu-1, degree 1-3."""

    ny: int = 30
    nu: int = 40
    degree: int = 2
    delay: int = 1
    constant: bool = True

    def __post_init__(self) -> None:
        if self.ny < 0 or self.nu < 0 or self.ny + self.nu == 0:
            raise IdentificationError(
                f"need ny >= 0, nu >= 0, ny + nu > 0 (got {self.ny}, {self.nu})")
        if not 1 <= self.degree <= 3:
            raise IdentificationError(f"degree must be 1, 2 or 3 (got {self.degree})")
        if self.delay < 1:
            raise IdentificationError(f"delay must be >= 1 (got {self.delay})")

    @property
    def max_lag(self) -> int:
        return max(self.ny, self.delay + self.nu - 1 if self.nu else 0)


@dataclass(frozen=True)
class NarxModel:
    """An identified polynomial NARX model y(k) = sum_i theta_i * term_i(k).

    Example:
        >>> import pmsm_sysid as ps
        >>> model = ps.identify("bags/paper_speed_nominal").model
        >>> model.term_names[:2], model.output_name
        (['const', 'y(k-1)'], 'speed')
    """

    terms: tuple[Term, ...]
    estimates: FloatArray
    std: FloatArray = field(default_factory=lambda: np.zeros(0))
    err: FloatArray = field(default_factory=lambda: np.zeros(0))
    sample_rate_hz: float = 1.0
    input_name: str = "thrust"
    output_name: str = "speed"
    structure: Structure | None = None

    def __post_init__(self) -> None:
        n = len(self.terms)
        fs = self.sample_rate_hz
        if not (isinstance(fs, (int, float)) and np.isfinite(fs) and fs > 0):
            raise IdentificationError(f"sample_rate_hz must be a positive number, got {fs!r}")
        if len(self.estimates) != n:
            raise IdentificationError(f"{n} terms but {len(self.estimates)} estimates")
        for name in ("std", "err"):
            arr = getattr(self, name)
            if len(arr) == 0:
                object.__setattr__(self, name, np.full(n, np.nan))
            elif len(arr) != n:
                raise IdentificationError(f"{n} terms but {len(arr)} values of {name}")

    @property
    def max_lag(self) -> int:
        return max((lag for t in self.terms for _, lag in t.factors), default=0)

    @property
    def term_names(self) -> list[str]:
        return [t.name for t in self.terms]

    def terms_json(self) -> list[dict[str, float | str]]:
        """The ``terms`` list of the identify JSON."""
        return [
            {"name": t.name, "estimate": float(e), "std": float(s), "err": float(r)}
            for t, e, s, r in zip(self.terms, self.estimates, self.std, self.err, strict=True)
        ]

    @classmethod
    def from_terms(
        cls, coefficients: Mapping[str, float], sample_rate_hz: float = 1.0, **kw: Any
    ) -> NarxModel:
        """Build a model from ``{"y(k-1)": 0.5, "u(k-1)": 1.0, ...}`` (handy in tests)."""
        terms = tuple(Term.parse(n) for n in coefficients)
        est = np.array([float(v) for v in coefficients.values()], dtype=np.float64)
        return cls(terms=terms, estimates=est, sample_rate_hz=sample_rate_hz, **kw)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> NarxModel:
        """Read the identify JSON; raises IdentificationError on bad content."""
        try:
            rows: Sequence[Mapping[str, Any]] = d["terms"]
            terms = tuple(Term.parse(str(r["name"])) for r in rows)
            est = np.array([_number(r["estimate"], f"term {r['name']}: estimate")
                            for r in rows], dtype=np.float64)
            std = np.array([_number(r.get("std"), f"term {r['name']}: std", True)
                            for r in rows], dtype=np.float64)
            err = np.array([_number(r.get("err"), f"term {r['name']}: err", True)
                            for r in rows], dtype=np.float64)
            st = d.get("structure")
            structure = (
                Structure(
                    ny=_integer(st["ny"], "structure ny"), nu=_integer(st["nu"], "structure nu"),
                    degree=_integer(st["degree"], "structure degree"),
                    delay=_integer(st.get("delay", 1), "structure delay"),
                    constant=bool(st.get("constant", True)),
                )
                if st else None
            )
            fs = _number(d.get("sample_rate_hz", 1.0), "sample_rate_hz")
        except (KeyError, TypeError, ValueError) as exc:
            raise IdentificationError(f"not a model JSON: {exc!r}") from exc
        if not np.all(np.isfinite(est)):
            raise IdentificationError("model has non-finite estimates")
        return cls(
            terms=terms, estimates=est, std=std, err=err, sample_rate_hz=fs,
            input_name=str(d.get("input", "thrust")), output_name=str(d.get("output", "speed")),
            structure=structure,
        )
