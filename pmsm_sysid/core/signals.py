"""Sampled recordings of one drive axis: thrust in, speed and position out.

Timing convention: speed/position stamped t_k are measured at t_k; the thrust
stamped t_k is applied from t_k to t_{k+1} (zero-order hold), so y(k) depends on u(k-1).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from .errors import DataError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Recording:
    """Aligned samples of one axis. All arrays have the same length N.

    ``t`` (s), ``thrust`` (N), ``speed`` (m/s) and ``position`` (m) are 1-D float arrays;
    ``sample_rate_hz`` is a float; ``speed_derived`` says speed was computed from position.

    Example:
        >>> import numpy as np, pmsm_sysid as ps
        >>> t = np.arange(1000) / 500.0
        >>> rec = ps.Recording(t=t, thrust=np.sin(t), speed=0 * t, position=0 * t,
        ...                    sample_rate_hz=500.0)
        >>> len(rec.window(100, 300))
        200
    """

    t: FloatArray
    thrust: FloatArray
    speed: FloatArray
    position: FloatArray
    sample_rate_hz: float
    speed_derived: bool = False
    source: str = ""
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("thrust", "speed", "position"):
            if len(getattr(self, name)) != n:
                got = len(getattr(self, name))
                raise DataError(f"recording: '{name}' has {got} samples, t has {n}")
        if not np.isfinite(self.sample_rate_hz) or self.sample_rate_hz <= 0:
            raise DataError(f"recording: sample rate must be positive, got {self.sample_rate_hz}")

    def __len__(self) -> int:
        return len(self.t)

    def signal(self, name: str) -> FloatArray:
        """Return the signal called ``thrust``, ``speed`` or ``position``."""
        if name not in ("thrust", "speed", "position"):
            raise DataError(f"unknown signal '{name}' (expected thrust, speed or position)")
        arr: FloatArray = getattr(self, name)
        return arr

    def window(self, start: int, stop: int) -> Recording:
        """Samples ``start:stop`` (0-based, half-open) as a new recording."""
        if not 0 <= start < stop <= len(self):
            raise DataError(f"range {start}:{stop} is outside the recording (0:{len(self)})")
        return replace(
            self,
            t=self.t[start:stop],
            thrust=self.thrust[start:stop],
            speed=self.speed[start:stop],
            position=self.position[start:stop],
        )


def estimate_sample_rate(t: FloatArray) -> float:
    """Sample rate from stamps: the inverse of the median step. Needs two or more stamps."""
    if len(t) < 2:
        raise DataError("need at least two samples to read a sample rate from the stamps")
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise DataError("stamps are not increasing: cannot read a sample rate")
    return 1.0 / dt


def derive_speed(t: FloatArray, position: FloatArray) -> FloatArray:
    """Speed from position by second-order central differences (one-sided at the ends).

    Central differences have zero phase lag at the sample instants, which is what
    inverse-dynamics identification needs; the result is marked ``speed_derived``.
    """
    if len(t) < 3:
        raise DataError("need at least three samples to derive speed from position")
    return np.asarray(np.gradient(position, t), dtype=np.float64)


def check_finite(rec: Recording) -> None:
    """Raise :class:`DataError` naming the first signal with NaN/Inf samples."""
    for name in ("t", "thrust", "speed", "position"):
        arr = getattr(rec, name)
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise DataError(
                f"'{name}' has {int(bad.sum())} non-finite samples (first at index {k})")
