"""Sim-to-real diagnosis: :func:`diagnose` and its result :class:`Diagnosis`."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from ..core.discrepancy.result import DiagnoseResult
from ..core.errors import OptionError
from ..core.physics.plant import Plant
from ..core.recording.signals import Recording
from ..core.recording.spans import MAX_SAMPLES, MIN_SPAN, SPANS, Excerpt, excerpt_of, plan_spans
from . import _checks
from ._json import plain
from .simulation import PlantLike, resolve_plant

RecordingLike = Recording | str | os.PathLike[str]


@dataclass(frozen=True)
class Diagnosis:
    """The result of :func:`diagnose`. :meth:`to_dict` is the JSON that
    ``pmsm-sysid diagnose --json`` writes; :meth:`summary` the lines it prints.

    Example:
        >>> import pmsm_sysid as ps
        >>> d = ps.diagnose("plants/nominal.yaml", "bags/paper_speed_coulomb", gfrf=False)
        >>> d.to_dict()["plant_file"], d.corrected.effects
        ('plants/nominal.yaml', ('coulomb_friction',))
        >>> print(d.corrected.to_yaml())  # doctest: +ELLIPSIS
        mass_kg: ...
    """

    result: DiagnoseResult
    """Found effects, their estimates, the fit before and after, where the mismatch lives."""
    real: Recording
    """The part of the real recording that was diagnosed: all of it, or the spans of a
    recording longer than ``max_samples`` end to end (see :attr:`excerpt`)."""
    sources: dict[str, str] = field(default_factory=dict)
    """``plant_file``, ``real``, ``validate``: the files given (paths only)."""
    excerpt: Excerpt | None = None
    """Which samples of the real recording were used (``total``, ``ranges()``)."""

    @property
    def corrected(self) -> Plant:
        """The plant with the found effects added (write it with ``.to_yaml()``)."""
        return self.result.corrected

    def summary(self) -> str:
        """A few lines for people: found effects, fit before and after, where it lived."""
        return self.result.summary()

    def to_dict(self) -> dict[str, Any]:
        """The diagnose JSON as plain Python data (non-finite numbers as None)."""
        out: dict[str, Any] = plain({**self.result.to_dict(), **self.sources})
        return out


def _recording(data: RecordingLike, label: str, namespace: str | None,
               joint: str | None = None) -> Recording:
    if isinstance(data, Recording):
        return data
    if isinstance(data, (str, os.PathLike)):
        from ..bagio.read import check_all_finite
        from .recordings import load_bag

        loaded = load_bag(data, namespace, joint=joint)
        check_all_finite(loaded, f"recording {data}", "diagnose")
        return loaded.recording
    raise OptionError(f"{label} must be a Recording or a bag path, got {type(data).__name__}")


def _excerpt(data: RecordingLike, label: str, namespace: str | None, max_samples: int,
             split: float | None, joint: str | None = None) -> Excerpt:
    """The spans of ``data`` the diagnosis uses (all of it within ``max_samples``); of a bag
    only those spans are read."""
    if isinstance(data, Recording):
        return excerpt_of(data, plan_spans(len(data), max_samples, split))
    if isinstance(data, (str, os.PathLike)):
        from .recordings import load_excerpt

        return load_excerpt(data, namespace, max_samples=max_samples, split=split, joint=joint,
                            use="diagnose")
    raise OptionError(f"{label} must be a Recording or a bag path, got {type(data).__name__}")


def diagnose(plant: PlantLike, real: RecordingLike, *, validate: RecordingLike | None = None,
             namespace: str | None = None, alpha: float = 1e-3, min_share: float = 0.01,
             replay: bool = True, gfrf: bool = True, sim: RecordingLike | None = None,
             sim_namespace: str | None = None, joint: str | None = None,
             sim_joint: str | None = None, max_samples: int = MAX_SAMPLES) -> Diagnosis:
    """Name the physics a plant model leaves out, by comparing it with a real recording.

    Locates the mismatch (equation error of the inverse dynamics over time, position,
    velocity and frequency), names the missing effects from a library of interpretable
    physics (forward regression, prewhitened F-tests with a Bonferroni correction, held-out
    confirmation), estimates their parameters with standard errors and builds the corrected
    plant.

    ``plant``: a :class:`Plant`, a plant YAML path, or None (the nominal motor). ``real``
    and ``validate``: :class:`Recording` objects or bag paths (``validate`` is held-out data;
    default: the last 30 % of ``real``; ``namespace`` and ``joint`` as in :func:`read_bag`).
    Options as ``pmsm-sysid diagnose``: ``alpha`` (family-wise false-alarm level of each
    selection step), ``min_share`` (smallest share of the mismatch an effect must explain),
    ``replay`` (short-horizon speed replay), ``gfrf`` (GFRF comparison with a noisy
    simulated twin), ``max_samples`` (samples used at most of each recording: a longer one
    is used in ten spans spread evenly over it, of a bag only those are read; the result's
    ``method.data_used`` and summary say which).

    ``sim``: instead of a plant, a recording of the user's own simulator (Gazebo, Isaac
    Sim, MuJoCo, Simulink, ...; a :class:`Recording` or a bag path, read with
    ``sim_namespace`` and ``sim_joint``); ``plant`` must then be None. Both recordings'
    plants are fitted (:func:`fit_plant`) and compared parameter by parameter against the
    combined standard error of both fits: ``to_dict()`` then holds ``reference:
    "sim_recording"``, ``sim_plant``, ``effects`` (what the real drive has beyond the
    simulation), ``sim_only`` (what the simulation has that the real drive lacks),
    ``changes`` (one row per parameter that differs) and the simulation's plant with the
    changes applied as ``corrected_plant``. The two recordings may differ in excitation,
    length, sample rate, loop, noise and topic layout.

    Example:
        >>> import pmsm_sysid as ps
        >>> d = ps.diagnose(None, "bags/paper_speed_coulomb", replay=False, gfrf=False)
        >>> [e["name"] for e in d.to_dict()["effects"]]
        ['coulomb_friction']
        >>> d.corrected.coulomb_friction is not None
        True
        >>> d = ps.diagnose(None, "bags/paper_speed_coulomb", sim="bags/paper_speed_nominal",
        ...                 replay=False, gfrf=False)
        >>> d.to_dict()["reference"], [c["parameter"] for c in d.to_dict()["changes"]]
        ('sim_recording', ['coulomb_friction.amplitude_n'])
    """
    from ..core.discrepancy import DiagnoseOptions
    from ..core.discrepancy import diagnose as run_diagnosis
    from ..core.discrepancy.against import diagnose_sim

    options = DiagnoseOptions(alpha=_checks.fraction("alpha", alpha),
                              min_share=_checks.fraction("min_share", min_share),
                              replay=bool(replay), gfrf=bool(gfrf),
                              max_samples=_checks.count("max_samples", max_samples,
                                                        SPANS * MIN_SPAN))
    if sim is not None and plant is not None:
        raise OptionError("give either a plant or a recording of the simulator (sim=), "
                          "not both")
    if sim is None:
        model, label = resolve_plant(plant)
    split = options.split if validate is None else None
    rec = _excerpt(real, "real", namespace, options.max_samples, split, joint)
    held = None if validate is None else _excerpt(validate, "validate", namespace,
                                                  options.max_samples, None, joint)
    sim_rec = None if sim is None else _excerpt(sim, "sim", sim_namespace,
                                                options.max_samples, options.split, sim_joint)
    _check_recordings((("sim", sim, sim_rec), ("real", real, rec),
                       ("validate", validate, held)), identify=sim is not None)
    sources = {}
    if sim is None and plant is not None and not isinstance(plant, Plant):
        sources["plant_file"] = label
    for key, value in (("real", real), ("validate", validate), ("sim", sim)):
        if isinstance(value, (str, os.PathLike)):
            sources[key] = str(value)
    if sim_rec is not None:
        return Diagnosis(diagnose_sim(sim_rec, rec, held, options), rec.joined, sources, rec)
    return Diagnosis(run_diagnosis(model, rec, held, options), rec.joined, sources, rec)


def _check_recordings(items: tuple[tuple[str, Any, Excerpt | None], ...],
                      identify: bool) -> None:
    """One sampling grid per recording (derivatives, filters and replays assume it: within
    each span used -- the gaps between spans are the spans' choice); with a simulator's
    recording, each must also be able to identify a plant."""
    from ..core.plantfit.physical import check_identifiable
    from ..core.selection.datacheck import check_sampling

    for name, given, ex in items:
        if ex is None:
            continue
        where = given if isinstance(given, (str, os.PathLike)) else name
        label = {"sim": "simulated recording", "validate": "held-out recording"}.get(
            name, "recording")
        for part in ex.parts:
            check_sampling(part.t, part.sample_rate_hz, f"{label} {where}")
        if identify:
            check_identifiable(ex.parts, f"{label} {where}")
