"""The live input side: align the signals that are present, derive speed when it is absent.

A drive with a position-only encoder (the EMPS rig, many linear axes) publishes thrust and
position but no speed. :class:`InputAligner` sits in front of the :class:`~.online.StampAligner`:

* ``speed_source="measured"``: the three signals are aligned as they are;
* ``speed_source="derived"``: thrust and position are aligned and speed is derived from the
  aligned positions by :func:`~.signals.derive_speed` (the causal backward difference that
  ``identify`` and ``diagnose`` use offline), sample by sample; speed messages are ignored
  (counted);
* ``speed_source="auto"`` (the identifier's default): messages are held until the speed
  source is clear: the first speed message makes it *measured*; ``decide_after`` position
  messages without one make it *derived*, unless ``speed_expected()`` says a speed publisher
  exists (then up to ``max_hold`` messages are held waiting for it). Held messages are then
  aligned in their arrival order, so nothing is lost to the decision.

Samples leave with one value per name in ``signals`` (speed included), so the window ring and
the fits see the same layout in every mode. Per-signal message counts with the first and
last stamp (:class:`SignalCount`) say what arrived and at which rate;
:func:`describe_inputs` turns them into the one-line account a run gives of its inputs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..errors import DataError
from ..recording.signals import SpeedDeriver
from .streaming import SIGNALS, AlignStats, Sample, StampAligner

SPEED_SOURCES = ("auto", "measured", "derived")
DECIDE_AFTER = 50  # position messages without speed before speed is derived (auto)
MAX_HOLD = 3000  # messages held at most while a speed publisher exists but is silent

_Held = tuple[str | None, int, tuple[float, ...]]  # signal (None: whole sample), stamp, values


@dataclass
class SignalCount:
    """Messages of one signal: how many, first and last ``header.stamp`` (ns)."""

    messages: int = 0
    first_ns: int | None = None
    last_ns: int | None = None

    def add(self, stamp_ns: int) -> None:
        self.messages += 1
        if self.first_ns is None or self.last_ns is None:
            self.first_ns = self.last_ns = stamp_ns
        elif stamp_ns > self.last_ns:  # in order: the only comparison made
            self.last_ns = stamp_ns
        elif stamp_ns < self.first_ns:
            self.first_ns = stamp_ns

    @property
    def rate_hz(self) -> float | None:
        """Message rate read from the stamps (None below two messages or one stamp)."""
        if self.messages < 2 or self.first_ns is None or self.last_ns is None:
            return None
        span = self.last_ns - self.first_ns
        return (self.messages - 1) * 1e9 / span if span > 0 else None

    def to_dict(self) -> dict[str, Any]:
        return {"messages": self.messages, "rate_hz": self.rate_hz}


class InputAligner:
    """Stamp alignment of the signals present, speed derived when absent (module doc)."""

    def __init__(self, signals: Sequence[str] = SIGNALS, speed_source: str = "auto", *,
                 tolerance_ns: int | None = None, period_ns: int | None = None,
                 decide_after: int = DECIDE_AFTER, max_hold: int = MAX_HOLD,
                 speed_expected: Callable[[], bool] | None = None) -> None:
        if speed_source not in SPEED_SOURCES:
            raise DataError(f"speed_source must be one of {', '.join(SPEED_SOURCES)}, got "
                            f"'{speed_source}'")
        self.signals = tuple(signals)
        derivable = "speed" in self.signals and "position" in self.signals
        if speed_source == "derived" and not derivable:
            raise DataError("speed can be derived only when both speed and position are signals")
        self._tolerance_ns, self._period_ns = tolerance_ns, period_ns
        self._decide_after, self._max_hold = decide_after, max_hold
        self._speed_expected = speed_expected or (lambda: False)
        self.counts = {s: SignalCount() for s in self.signals}
        self._held: list[_Held] = []
        self._held_positions = 0
        self._inner: StampAligner | None = None
        self._deriver: SpeedDeriver[Sample] = SpeedDeriver()
        self.ignored = 0  # speed messages not used because speed is derived
        self._unaligned = 0  # counted before the inner aligner exists
        self._emitted = 0
        self._messages = 0  # a whole sample (JointState) counts as one per signal
        self.mode = "undecided"
        if speed_source == "measured" or not derivable:
            self._decide("measured")
        elif speed_source == "derived":
            self._decide("derived")

    # -- public ------------------------------------------------------------------------
    @property
    def speed_derived(self) -> bool:
        return self.mode == "derived"

    @property
    def samples_emitted(self) -> int:
        return self._emitted

    @property
    def period_ns(self) -> int | None:
        return self._inner.period_ns if self._inner is not None else None

    @property
    def stats(self) -> AlignStats:
        inner = self._inner.stats if self._inner is not None else AlignStats(0, 0, 0, 0, 0,
                                                                              0, 0)
        return AlignStats(
            messages=self._messages,
            samples=self._emitted, unaligned=inner.unaligned + self.ignored + self._unaligned,
            out_of_order=inner.out_of_order, duplicates=inner.duplicates, gaps=inner.gaps,
            samples_missing=inner.samples_missing, restarts=inner.restarts,
            rate_changes=inner.rate_changes)

    def push(self, signal: str, stamp_ns: int, value: float) -> list[Sample]:
        """One message of one signal; the samples it completes, in stamp order."""
        if signal not in self.counts:
            raise DataError(f"unknown signal '{signal}' (expected one of {self.signals})")
        self.counts[signal].add(stamp_ns)
        self._messages += 1
        if self.mode == "derived" and signal == "speed":
            self.ignored += 1
            return []
        if self.mode == "undecided":
            return self._hold((signal, stamp_ns, (float(value),)), signal == "speed",
                              signal == "position")
        assert self._inner is not None
        return self._complete(self._inner.push(signal, stamp_ns, float(value)))

    def push_sample(self, stamp_ns: int, values: Sequence[float]) -> list[Sample]:
        """One sample holding every signal (JointState); a NaN speed counts as absent."""
        if len(values) != len(self.signals):
            raise DataError(f"sample has {len(values)} values, expected {len(self.signals)}")
        for s in self.signals:
            self.counts[s].add(stamp_ns)
        self._messages += len(self.signals)
        vals = tuple(float(v) for v in values)
        if self.mode == "undecided":
            has_speed = "speed" in self.signals and math.isfinite(
                vals[self.signals.index("speed")])
            return self._hold((None, stamp_ns, vals), has_speed, not has_speed)
        return self._take((None, stamp_ns, vals))

    def count_unaligned(self, n_messages: int) -> None:
        """Messages that carried no usable sample (e.g. a JointState without the joint)."""
        self._messages += n_messages
        if self._inner is not None:
            self._inner.count_unaligned(n_messages)
        else:
            self._unaligned += n_messages

    def flush(self) -> list[Sample]:
        """End of stream: decide if still undecided, emit what is complete."""
        out: list[Sample] = []
        if self.mode == "undecided":
            out = self._decide("derived" if self._held_positions else "measured")
        assert self._inner is not None
        out.extend(self._complete(self._inner.flush()))
        if self.speed_derived:  # a lone first sample never got its speed
            out.extend(self._complete([], final=True))
        return out

    # -- internals ---------------------------------------------------------------------
    def _hold(self, msg: _Held, speed: bool, position: bool) -> list[Sample]:
        self._held.append(msg)
        self._held_positions += int(position)
        if speed:
            return self._decide("measured")
        if self._held_positions >= self._decide_after and (
                len(self._held) >= self._max_hold or not self._speed_expected()):
            return self._decide("derived")
        return []

    def _decide(self, mode: str) -> list[Sample]:
        self.mode = mode
        used = tuple(s for s in self.signals if not (mode == "derived" and s == "speed"))
        self._inner = StampAligner(used, tolerance_ns=self._tolerance_ns,
                                   period_ns=self._period_ns)
        if self._unaligned:
            self._inner.count_unaligned(self._unaligned)
            self._unaligned = 0
        held, self._held = self._held, []
        out: list[Sample] = []
        for msg in held:
            if mode == "derived" and msg[0] == "speed":
                self.ignored += 1
            else:
                out.extend(self._take(msg))
        return out

    def _take(self, msg: _Held) -> list[Sample]:
        assert self._inner is not None
        signal, stamp, values = msg
        if signal is not None:
            return self._complete(self._inner.push(signal, stamp, values[0]))
        if self.speed_derived:
            k = self.signals.index("speed")
            values = values[:k] + values[k + 1:]
        return self._complete(self._inner.push_sample(stamp, values))

    def _complete(self, samples: list[Sample], final: bool = False) -> list[Sample]:
        """Samples with one value per signal: derived speed inserted where needed."""
        if not self.speed_derived:
            self._emitted += len(samples)
            return samples
        out: list[Sample] = []
        assert self._inner is not None
        used = self._inner.signals
        for s in samples:
            pos = s.values[used.index("position")]
            for payload, v in self._deriver.push(s.stamp_ns, pos, s):
                out.append(self._with_speed(payload, v))
        if final:
            out.extend(self._with_speed(p, math.nan) for p in self._deriver.drain())
        self._emitted += len(out)
        return out

    def _with_speed(self, s: Sample, speed: float) -> Sample:
        vals = dict(zip(self._inner.signals if self._inner else (), s.values, strict=True))
        vals["speed"] = speed
        return Sample(s.index, s.stamp_ns, tuple(vals[name] for name in self.signals))


@dataclass(frozen=True)
class InputReport:
    """What a run expected on its inputs, what arrived (with rates), what never came."""

    expected: tuple[str, ...]
    arrived: dict[str, dict[str, Any]]
    missing: tuple[str, ...]
    speed: str
    samples: int
    problem: str | None

    def to_dict(self) -> dict[str, Any]:
        return {"expected": list(self.expected), "arrived": self.arrived,
                "missing": list(self.missing), "speed": self.speed,
                "samples_aligned": self.samples, "problem": self.problem}

    def line(self) -> str:
        """One line for the log and the run's summary."""
        def rate(topic: str) -> str:
            r = self.arrived[topic]["rate_hz"]
            return f"{topic} {r:.6g} Hz" if r else f"{topic} ({self.arrived[topic]['messages']})"

        got = ", ".join(rate(t) for t in self.expected if t in self.arrived) or "nothing"
        text = f"inputs: {got}"
        if self.missing:
            text += f"; never came: {', '.join(self.missing)}"
        text += f"; speed {self.speed}; {self.samples} samples aligned"
        return f"{self.problem} ({text})" if self.problem else text


SPEED_TEXT = {"measured": "measured", "derived": "derived from position",
              "undecided": "not known yet"}


def describe_inputs(topics: Mapping[str, str], counts: Mapping[str, SignalCount], mode: str,
                    samples: int, needed: Sequence[str] = ("thrust", "position")) -> InputReport:
    """The account of the inputs: ``topics`` maps signal -> topic (several signals may share
    one topic, e.g. JointState), ``counts`` holds the messages per signal, ``needed`` the
    signals without which nothing can be aligned."""
    expected = tuple(dict.fromkeys(topics.values()))
    arrived: dict[str, dict[str, Any]] = {}
    for signal, topic in topics.items():
        c = counts.get(signal)
        if c is not None and c.messages and topic not in arrived:
            arrived[topic] = c.to_dict()
    missing = tuple(t for t in expected if t not in arrived)
    absent = tuple(dict.fromkeys(topics[s] for s in needed
                                 if s in topics and topics[s] not in arrived))
    problem = None
    if not arrived:
        problem = f"no messages on {', '.join(expected)}: nothing to identify"
    elif absent:
        problem = f"no messages on {' and '.join(absent)}: nothing could be aligned"
    elif samples == 0 and mode != "undecided":
        problem = ("messages arrived but no sample aligned: their header stamps do not match "
                   "within the tolerance")
    return InputReport(expected, arrived, missing, SPEED_TEXT.get(mode, mode), samples,
                       problem)
