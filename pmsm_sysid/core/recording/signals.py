"""Sampled recordings of one drive axis: thrust in, speed and position out.

Timing convention: speed/position stamped t_k are measured at t_k; the thrust
stamped t_k is applied from t_k to t_{k+1} (zero-order hold), so y(k) depends on u(k-1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError

FloatArray = NDArray[np.float64]
P = TypeVar("P")


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
    """Speed from position by the causal backward difference ``(x_k - x_{k-1}) / (t_k - t_{k-1})``.

    This is the one differentiator of the package: offline (recordings without a speed
    topic, ``identify``, ``diagnose``) and live (the identifier node, sample by sample through
    :class:`SpeedDeriver`) give the same numbers. It uses only the current and the previous
    sample, so it can run live; each value is the exact mean speed over the sample interval
    that ends at ``t_k`` (half a sample behind the instantaneous speed; gain
    ``sinc(f/fs)``, 0.64 at Nyquist), and it keeps the timing convention: the speed at
    ``t_k`` depends on the thrust up to ``t_{k-1}`` only. The step is read from the stamps,
    so any sample rate works and a lost sample gives the mean speed over the gap. The first
    sample, which has no predecessor, takes the second one's value. The result is marked
    ``speed_derived``.
    """
    t = np.asarray(t, dtype=np.float64)
    x = np.asarray(position, dtype=np.float64)
    if len(t) < 2 or len(x) != len(t):
        raise DataError("need at least two samples (stamp and position) to derive speed")
    dt = np.diff(t)
    if not np.all(dt > 0):
        raise DataError("stamps must increase to derive speed from position")
    v = np.empty(len(x), dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # callers check finiteness
        v[1:] = np.diff(x) / dt
    v[0] = v[1]
    return v


class SpeedDeriver(Generic[P]):
    """:func:`derive_speed` sample by sample, for a live stream of aligned samples.

    :meth:`push` takes (stamp in ns, position, payload) and returns ``(payload, speed)`` for
    the samples whose speed is now known: nothing for the very first sample (it waits for
    the second, whose value it takes, as :func:`derive_speed` does), then one per sample.
    A non-finite position comes back at once with a NaN speed and is passed over (the next
    speed spans it, as offline alignment drops it); a stamp that does not increase starts
    the stream again (the publisher's clock restarted; a first sample still waiting then
    comes back with a NaN speed).
    """

    def __init__(self) -> None:
        self._last: tuple[int, float] | None = None
        self._first: P | None = None  # the first sample, waiting for the second
        self._waiting = False

    def push(self, stamp_ns: int, position: float, payload: P) -> list[tuple[P, float]]:
        nan = float("nan")
        if not math.isfinite(position):
            return [(payload, nan)]
        last, self._last = self._last, (stamp_ns, position)
        out: list[tuple[P, float]] = []
        if last is None or stamp_ns <= last[0]:
            if self._waiting:
                out.append((self._first, nan))  # type: ignore[arg-type]
            self._first, self._waiting = payload, True
            return out
        t = np.array([last[0], stamp_ns], dtype=np.float64) / 1e9
        v = float(derive_speed(t, np.array([last[1], position], dtype=np.float64))[1])
        if self._waiting:
            out.append((self._first, v))  # type: ignore[arg-type]
            self._first, self._waiting = None, False
        out.append((payload, v))
        return out

    def drain(self) -> list[P]:
        """The first sample if it is still waiting for a second one (end of stream)."""
        out = [self._first] if self._waiting and self._first is not None else []
        self._first, self._waiting = None, False
        return out


def check_finite(rec: Recording) -> None:
    """Raise :class:`DataError` naming the first signal with NaN/Inf samples."""
    for name in ("t", "thrust", "speed", "position"):
        arr = getattr(rec, name)
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise DataError(
                f"'{name}' has {int(bad.sum())} non-finite samples (first at index {k})")
