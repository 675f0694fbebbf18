"""Stamp alignment of the three input streams into one :class:`Recording`.

One sample is the thrust, speed and position messages that carry the same ``header.stamp``.
Real recordings jitter, so stamps are matched within a tolerance (default: half the sample
period, read from the position stamps by :func:`robust_period`, i.e. the median step refined
by averaging the steps near it). Nothing is invented:

1. messages with a non-finite stamp or value are dropped (``n_nonfinite``);
2. each stream is sorted by stamp (stable); a message stamped earlier than one already seen
   on its stream counts as out of order (``n_out_of_order``; kept, just re-sorted);
3. a message whose stamp equals one already kept on its stream is dropped as a duplicate
   (``n_duplicates``; the first received wins);
4. thrust and speed are matched to position by *mutual nearest neighbour* within the
   tolerance: a pair is kept only if each is the other's nearest stamp, so every message
   is used at most once and the matching keeps the stamp order;
5. a sample is a position stamp matched on every present stream; the sample's stamp is the
   position stamp (speed and position are measured at t_k). Every other kept message is
   counted in ``n_unaligned``.

So, with k the number of streams present (2 without speed, else 3):
``n_thrust + n_speed + n_position == k*n_aligned + n_nonfinite + n_duplicates + n_unaligned``.

A missing speed stream is derived from position (:func:`~.signals.derive_speed`, the causal
backward difference the live identifier uses too) and marked ``speed_derived``. Steps longer
than 1.5 periods count as gaps.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import DataError
from .signals import FloatArray, Recording, derive_speed

IntArray = NDArray[np.intp]
Stream = tuple[ArrayLike, ArrayLike]

GAP_FACTOR = 1.5  # a step longer than this many sample periods is a gap


@dataclass(frozen=True)
class AlignReport:
    """What alignment kept, dropped and noticed. Message counts are summed over streams."""

    n_thrust: int
    n_speed: int
    n_position: int
    n_aligned: int
    n_unaligned: int
    n_duplicates: int
    n_out_of_order: int
    n_nonfinite: int
    n_gaps: int
    speed_derived: bool
    tolerance_s: float

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (JSON-ready)."""
        return asdict(self)

    def summary(self) -> str:
        """One human-readable line."""
        speed = "derived from position" if self.speed_derived else str(self.n_speed)
        return (
            f"{self.n_aligned} samples aligned (thrust {self.n_thrust}, speed {speed}, "
            f"position {self.n_position} messages); {self.n_unaligned} unaligned, "
            f"{self.n_duplicates} duplicates, {self.n_out_of_order} out of order, "
            f"{self.n_nonfinite} non-finite, {self.n_gaps} gaps; "
            f"tolerance {self.tolerance_s * 1e3:.4g} ms"
        )


@dataclass(frozen=True)
class _Clean:
    """One stream after dropping non-finite and duplicate messages, sorted by stamp."""

    t: FloatArray
    v: FloatArray
    n_in: int
    n_nonfinite: int
    n_duplicates: int
    n_out_of_order: int


def _as_1d(name: str, what: str, arr: ArrayLike) -> FloatArray:
    try:
        out = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name}: {what} are not numbers ({exc})") from exc
    if out.ndim != 1:
        raise DataError(f"{name}: {what} must be one-dimensional, got shape {out.shape}")
    return out


def _clean(name: str, stream: Stream) -> _Clean:
    """Steps 1-3 of the module docstring on one stream."""
    t = _as_1d(name, "stamps", stream[0])
    v = _as_1d(name, "values", stream[1])
    if len(t) != len(v):
        raise DataError(f"{name}: {len(t)} stamps but {len(v)} values")
    finite = np.isfinite(t) & np.isfinite(v)
    tf, vf = t[finite], v[finite]
    n_ooo = 0
    if len(tf) > 1:
        n_ooo = int(np.count_nonzero(tf[1:] < np.maximum.accumulate(tf)[:-1]))
    order = np.argsort(tf, kind="stable")
    ts, vs = tf[order], vf[order]
    keep = np.ones(len(ts), dtype=bool)
    keep[1:] = ts[1:] != ts[:-1]
    return _Clean(
        t=ts[keep], v=vs[keep], n_in=len(t), n_nonfinite=int(len(t) - len(tf)),
        n_duplicates=int(len(ts) - np.count_nonzero(keep)), n_out_of_order=n_ooo,
    )


def _nearest(a: FloatArray, b: FloatArray) -> IntArray:
    """Index into sorted ``b`` of the nearest stamp to each of ``a`` (ties go left)."""
    k = np.searchsorted(b, a)
    left = np.clip(k - 1, 0, len(b) - 1)
    right = np.clip(k, 0, len(b) - 1)
    take_right = np.abs(b[right] - a) < np.abs(a - b[left])
    return np.where(take_right, right, left).astype(np.intp)


def mutual_nearest(r: FloatArray, s: FloatArray, tol: float) -> tuple[IntArray, IntArray]:
    """Pairs (i, j) with r[i], s[j] each other's nearest stamp and |r[i]-s[j]| <= tol.

    Both inputs sorted, strictly increasing. Returns index arrays, both strictly increasing.
    """
    if len(r) == 0 or len(s) == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    j = _nearest(r, s)
    back = _nearest(s, r)
    i = np.arange(len(r), dtype=np.intp)
    ok = (back[j] == i) & (np.abs(r - s[j]) <= tol)
    ii, jj = i[ok], j[ok]
    # Mutual nearest neighbours cannot cross in 1-D; keep the guarantee explicit anyway.
    mono = np.ones(len(jj), dtype=bool)
    if len(jj) > 1:
        mono[1:] = jj[1:] > np.maximum.accumulate(jj)[:-1]
    return ii[mono], jj[mono]


def robust_period(t: ArrayLike) -> float:
    """Sample period of increasing stamps: the mean of the steps within 5 % of the median
    step. Gaps, stray stamps and the steps of a stretch recorded at another rate are left out
    (as by a median) but quantised jitter averages out (a plain median of steps of 0.99998
    and 1.00002 ms is biased); symmetric jitter leaves the mean unbiased."""
    steps = np.diff(np.asarray(t, dtype=np.float64))
    med = float(np.median(steps))
    typical = steps[np.abs(steps - med) <= 0.05 * med]
    return float(np.mean(typical)) if len(typical) else med


def _period(t: FloatArray, what: str) -> float:
    if len(t) < 2:
        raise DataError(f"{what}: fewer than two usable stamps, cannot read a sample period")
    dt = robust_period(t)
    if not (np.isfinite(dt) and dt > 0):
        raise DataError(f"{what}: cannot read a sample period from the stamps")
    return dt


def _tolerance(tolerance_s: float | None, pos: _Clean) -> float:
    if tolerance_s is None:
        return 0.5 * _period(pos.t, "position")
    tol = float(tolerance_s)
    if not (np.isfinite(tol) and tol >= 0):
        raise DataError(f"alignment tolerance must be a finite number >= 0, got {tolerance_s}")
    return tol


def _match(cx: _Clean, cu: _Clean, cv: _Clean | None,
           tol: float) -> tuple[IntArray, IntArray, IntArray | None]:
    """Indices into position, thrust (and speed) of the samples present on every stream."""
    iu, ju = mutual_nearest(cx.t, cu.t, tol)
    if cv is None:
        return iu, ju, None
    iv, jv = mutual_nearest(cx.t, cv.t, tol)
    common, a, b = np.intersect1d(iu, iv, assume_unique=True, return_indices=True)
    return common.astype(np.intp), ju[a], jv[b]


def align_streams(
    thrust: Stream,
    speed: Stream | None,
    position: Stream,
    *,
    tolerance_s: float | None = None,
    source: str = "",
) -> tuple[Recording, AlignReport]:
    """Align (stamps, values) streams into a :class:`Recording`; see the module docstring.

    Stamps are in seconds. Raises :class:`DataError` if fewer than 3 samples align.
    """
    cu, cx = _clean("thrust", thrust), _clean("position", position)
    cv = _clean("speed", speed) if speed is not None else None
    tol = _tolerance(tolerance_s, cx)
    sel_x, sel_u, sel_v = _match(cx, cu, cv, tol)
    n = len(sel_x)
    if n < 3:
        raise DataError(
            f"only {n} samples align within {tol * 1e3:.4g} ms "
            f"(thrust {cu.n_in}, speed {cv.n_in if cv else 'none'}, position {cx.n_in} messages)"
        )
    t = cx.t[sel_x]
    pos = cx.v[sel_x]
    if cv is not None and sel_v is not None:
        spd = cv.v[sel_v]
    else:
        spd = derive_speed(t, pos)
        if not np.all(np.isfinite(spd)):
            raise DataError("speed derived from position is not finite (position values overflow)")
    streams = [c for c in (cu, cv, cx) if c is not None]
    kept = sum(len(c.t) for c in streams)
    dt = _period(t, "aligned samples")
    report = AlignReport(
        n_thrust=cu.n_in, n_speed=cv.n_in if cv else 0, n_position=cx.n_in,
        n_aligned=n, n_unaligned=kept - len(streams) * n,
        n_duplicates=sum(c.n_duplicates for c in streams),
        n_out_of_order=sum(c.n_out_of_order for c in streams),
        n_nonfinite=sum(c.n_nonfinite for c in streams),
        n_gaps=int(np.count_nonzero(np.diff(t) > GAP_FACTOR * dt)),
        speed_derived=cv is None, tolerance_s=tol,
    )
    rec = Recording(
        t=t, thrust=cu.v[sel_u], speed=spd, position=pos, sample_rate_hz=1.0 / dt,
        speed_derived=cv is None, source=source,
    )
    return rec, report
