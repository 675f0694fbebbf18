"""A physical plant from any recording: :func:`fit_plant` and its result :class:`PlantFit`."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from ..core.discrepancy.fitted import PlantFitResult
from ..core.physics.plant import Plant
from ..core.plantfit.found import FoundEffect
from ..core.recording.signals import Recording
from ..core.recording.spans import MAX_SAMPLES, MIN_SPAN, SPANS, Excerpt
from . import _checks
from ._json import plain

RecordingLike = Recording | str | os.PathLike[str]


@dataclass(frozen=True)
class PlantFit:
    """The result of :func:`fit_plant`. :meth:`to_dict` is the JSON that
    ``pmsm-sysid fit-plant --json`` writes; :meth:`summary` the lines it prints.

    Example:
        >>> import pmsm_sysid as ps
        >>> fit = ps.fit_plant("bags/paper_speed_coulomb")
        >>> round(fit.plant.mass_kg, 1), fit.plant.effects  # the blocks written
        (2.3, ('coulomb_friction',))
        >>> sorted(fit.to_dict())[:4]
        ['effects', 'fit', 'method', 'notes']
    """

    result: PlantFitResult
    recording: Recording
    """The recording the plant was fitted from: all of it, or the spans of a recording
    longer than ``max_samples`` end to end (see :attr:`excerpt`)."""
    sources: dict[str, str] = field(default_factory=dict)
    """``recording``, ``validate``: the files given (paths only)."""
    excerpt: Excerpt | None = None
    """Which samples of the recording were used (``total``, ``ranges()``)."""

    @property
    def plant(self) -> Plant:
        """The fitted plant: mass, viscous damping, the recording's sample rate and the
        effect blocks found (write it with ``.to_yaml()``)."""
        return self.result.plant

    @property
    def std(self) -> dict[str, Any]:
        """Standard errors with the keys and nesting of the plant file, e.g.
        ``{"mass_kg": 0.01, "coulomb_friction": {"amplitude_n": 0.2}}``."""
        return self.result.std

    @property
    def effects(self) -> tuple[FoundEffect, ...]:
        """The effects found (as in ``diagnose``: name, params, params_std, significance,
        explains, confidence), then any ``unexplained`` structure (not in the plant)."""
        return self.result.effects

    def summary(self) -> str:
        """A few lines for people: mass and viscous damping, effects, fit."""
        return self.result.summary()

    def to_dict(self) -> dict[str, Any]:
        """The fit-plant JSON as plain Python data (non-finite numbers as None)."""
        out: dict[str, Any] = plain({**self.result.to_dict(), **self.sources})
        return out


def load(data: RecordingLike, label: str, namespace: str | None,
         joint: str | None = None) -> Recording:
    """A :class:`Recording`, or the recording of a bag path."""
    from .diagnosis import _recording

    return _recording(data, label, namespace, joint)


def fit_plant(recording: RecordingLike, *, validate: RecordingLike | None = None,
              namespace: str | None = None, alpha: float = 1e-3,
              min_share: float = 0.01, joint: str | None = None,
              max_samples: int = MAX_SAMPLES) -> PlantFit:
    """Identify the physical plant of one axis from a recording of it.

    Mass and viscous damping are always estimated (instrumental variables built from the
    thrust, iterated until the reference plant settles); every effect of the library the
    recording shows (Coulomb and Stribeck friction, force offset, cogging, thrust ripple,
    thrust lag, transport delay, spring) is selected and estimated with the statistics of
    :func:`diagnose`: prewhitened F-tests with a Bonferroni correction, held-out
    confirmation, standard errors and a confidence. Structure no library effect explains is
    reported as ``unexplained`` and left out of the plant.

    ``recording`` and ``validate`` (held-out data; default: the last 30 % of
    ``recording``): :class:`Recording` objects or bag paths (any layout ``read_bag``
    reads, topics or JointState); ``namespace`` picks the topics, ``joint`` the axis's joint
    of a JointState recording of several joints. ``alpha``, ``min_share`` and
    ``max_samples`` (a longer recording is used in ten spans spread evenly over it; of a
    bag only those are read) as in :func:`diagnose`. The plant's ``sample_rate_hz`` is the
    recording's; it drives ``simulate``, the sim node and ``diagnose --plant``.

    Raises :class:`PmsmSysidError` before any work when the recording cannot identify a
    plant (too short, no motion, no excitation), saying what it needs.

    Example:
        >>> import pmsm_sysid as ps
        >>> fit = ps.fit_plant("bags/paper_speed_nominal")
        >>> fit.effects, round(fit.std["mass_kg"], 3) < 0.05
        ((), True)
        >>> fit.plant.sample_rate_hz
        500.0
    """
    from ..core.discrepancy.fitted import fit_plant as run_fit
    from ..core.plantfit.fit import FitOptions
    from ..core.plantfit.physical import check_identifiable
    from ..core.selection.datacheck import check_sampling
    from .diagnosis import _excerpt

    opts = FitOptions(alpha=_checks.fraction("alpha", alpha),
                      min_share=_checks.fraction("min_share", min_share),
                      max_samples=_checks.count("max_samples", max_samples, SPANS * MIN_SPAN))
    split = opts.split if validate is None else None
    rec = _excerpt(recording, "recording", namespace, opts.max_samples, split, joint)
    held = None if validate is None else _excerpt(validate, "validate", namespace,
                                                  opts.max_samples, None, joint)
    sources: dict[str, str] = {}
    for key, given, ex in (("recording", recording, rec), ("validate", validate, held)):
        if ex is None:
            continue
        where = str(given) if isinstance(given, (str, os.PathLike)) else key
        if isinstance(given, (str, os.PathLike)):
            sources[key] = str(given)
        for part in ex.parts:
            check_sampling(part.t, part.sample_rate_hz, f"recording {where}")
        check_identifiable(ex.parts, f"recording {where}")
    return PlantFit(run_fit(rec, held, opts), rec.joined, sources, rec)


__all__ = ["PlantFit", "fit_plant"]
