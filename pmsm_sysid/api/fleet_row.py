"""One row of the fleet table: :func:`recording_row` analyses one axis of one recording.

A plain function of the API (one recording in, one row out), so a scheduler only has to
call it: the fleet runs it on Dask workers, and anything else (a loop, a job queue) can too.
It never raises on a bad recording: the row then has ``status: error`` and the one-line
reason in ``error``.
"""

from __future__ import annotations

import functools
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.errors import OptionError, PmsmSysidError
from ..core.physics.plant import Plant
from ..core.recording.spans import MAX_SAMPLES

if TYPE_CHECKING:
    from ..core.discrepancy import DiagnoseOptions
    from ..core.discrepancy.fitted import PlantFitResult
    from ..core.recording.spans import Excerpt

#: The modules a row imports (lazily, as it needs them): a scheduler that starts its
#: workers from a fork server preloads them there, so no worker imports them again.
ROW_MODULES = ("pmsm_sysid.api.fleet_row", "pmsm_sysid.api.plantfit",
               "pmsm_sysid.api.diagnosis", "pmsm_sysid.api.recordings", "pmsm_sysid.bagio.spans",
               "pmsm_sysid.core.fleet", "pmsm_sysid.core.discrepancy.fitted",
               "pmsm_sysid.core.discrepancy.against")

#: Recordings shorter than this (s) are refused by default: a few seconds of data give
#: parameters too uncertain to follow over time.
MIN_DURATION_S = 5.0


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _options(alpha: float, min_share: float, max_samples: int) -> DiagnoseOptions:
    """The options of both the fit and the diagnosis of a row (equation error only: no
    replay, no GFRF comparison)."""
    from ..core.discrepancy import DiagnoseOptions

    return DiagnoseOptions(alpha=alpha, min_share=min_share, max_samples=max_samples,
                           replay=False, gfrf=False)


def _read(path: str | os.PathLike[str], namespace: str | None, joint: str | None,
          opts: DiagnoseOptions, label: str) -> Excerpt:
    """The spans of the recording that the fit and the diagnosis use (all of it within
    ``max_samples``; of a longer one only those spans are read), checked for one sampling
    grid within each span and finite samples."""
    from ..core.selection.datacheck import check_sampling
    from .recordings import load_excerpt

    ex = load_excerpt(path, namespace, max_samples=opts.max_samples, split=opts.split,
                      joint=joint, use="diagnose")
    for part in ex.parts:
        check_sampling(part.t, part.sample_rate_hz, f"{label} {os.fspath(path)}")
    return ex


def _fit_and_diagnose(ex: Excerpt, plant: Plant, opts: DiagnoseOptions) -> dict[str, Any]:
    """The plant part of the row: the fitted physical plant (:func:`fit_plant`), and the
    diagnosis of the reference plant (:func:`diagnose`) on the same samples."""
    from ..core.discrepancy import diagnose as run_diagnosis
    from ..core.discrepancy.fitted import fit_plant as run_fit
    from ..core.fleet import diagnosis_columns, plant_columns
    from .diagnosis import Diagnosis
    from .plantfit import PlantFit

    fit = PlantFit(run_fit(ex, None, opts), ex.joined, {}, ex).to_dict()
    found = Diagnosis(run_diagnosis(plant, ex, None, opts), ex.joined, {}, ex).to_dict()
    row = plant_columns(fit.get("plant") or {}, fit.get("std") or {}, fit.get("effects") or [])
    row.update(diagnosis_columns(found))
    row["effects"] = [str(e.get("name")) for e in fit.get("effects") or []]
    return row


@functools.lru_cache(maxsize=4)
def _sim_fit(path: str, namespace: str | None, opts: DiagnoseOptions,
             content: str | None) -> tuple[Excerpt, PlantFitResult]:
    """The simulator's recording and its fitted plant, once per process (a worker analysing
    many recordings against one simulation fits it once; ``content`` keys the cache to the
    file's content)."""
    from ..core.discrepancy.fitted import fit_plant

    ex = _read(path, namespace, None, opts, "simulated recording")
    return ex, fit_plant(ex, None, opts)


def _against_sim(ex: Excerpt, sim: str, sim_namespace: str | None, sim_content: str | None,
                 opts: DiagnoseOptions) -> dict[str, Any]:
    """The plant part of the row with a simulator's recording as the reference: the real
    recording's fitted plant (fitted once, inside the comparison) and the comparison."""
    from ..core.discrepancy.against import diagnose_sim
    from ..core.fleet import diagnosis_columns, plant_columns
    from .diagnosis import Diagnosis

    sim_ex, sim_fit = _sim_fit(sim, sim_namespace, opts, sim_content)
    found = Diagnosis(diagnose_sim(sim_ex, ex, None, opts, sim_fit=sim_fit), ex.joined, {},
                      ex).to_dict()
    real = dict(found.get("real_plant") or {})
    std = real.pop("std", None) or {}
    effects = (found.get("real_fit") or {}).get("effects") or []
    row = plant_columns(real, std, effects)
    row.update(diagnosis_columns(found))
    row["effects"] = [str(e.get("name")) for e in effects]
    return row


def recording_row(path: str | os.PathLike[str], plant: Plant | None = None, *,
                  namespace: str | None = None, joint: str | None = None,
                  axis: str | None = None, content_sha256: str | None = None,
                  min_duration_s: float = MIN_DURATION_S, alpha: float = 1e-3,
                  min_share: float = 0.01, max_samples: int = MAX_SAMPLES,
                  sim: str | os.PathLike[str] | None = None, sim_namespace: str | None = None,
                  sim_sha256: str | None = None) -> dict[str, Any]:
    """Analyse one axis of one recording into one row of the fleet table.

    Reads the recording (``namespace``: its topic namespace or JointState topic; ``joint``:
    the JointState joint; None finds the one axis), fits its physical plant
    (:func:`pmsm_sysid.fit_plant`) and diagnoses the reference on the same samples
    (:func:`pmsm_sysid.diagnose`, equation error only: no replay, no GFRF comparison). A
    recording longer than ``max_samples`` is used in ten spans spread evenly over it, and
    only those are read, as ``fit-plant`` and ``diagnose`` do. The reference is ``plant``,
    or ``sim``, a recording of the user's simulator (read with ``sim_namespace``; fitted
    once per process, ``sim_sha256`` its content key). ``axis`` names the row's axis
    (default: the namespace or the joint). Returns the row as a dict of the fleet table's
    columns (:func:`pmsm_sysid.core.fleet.columns`); times in s since 1970 (UTC);
    ``duration_s`` is the whole recording's.
    """
    if (plant is None) == (sim is None):
        raise OptionError("give the reference as a plant or as a simulator's recording "
                          "(sim=), one of the two")
    from ..core.fleet import empty_row

    started = time.perf_counter()
    row = empty_row()
    row.update(recording=str(path), status="error", content_sha256=content_sha256)
    try:
        row.update(_analyse(Path(path), plant, row, (namespace, joint, axis),
                            (min_duration_s, alpha, min_share, max_samples),
                            (sim, sim_namespace, sim_sha256)))
        row.update(status="ok", error=None)
    except PmsmSysidError as exc:
        row["error"] = _one_line(str(exc))
    except MemoryError:
        row["error"] = f"{path}: out of memory while analysing it"
    except Exception as exc:  # a fault on one recording must not end the batch
        row["error"] = _one_line(f"{path}: internal error ({type(exc).__name__}: {exc})")
    row["analysed_at"] = time.time()
    row["elapsed_s"] = time.perf_counter() - started
    return row


def _analyse(path: Path, plant: Plant | None, row: dict[str, Any],
             which: tuple[str | None, str | None, str | None],
             numbers: tuple[float, float, float, int],
             reference: tuple[str | os.PathLike[str] | None, str | None, str | None],
             ) -> dict[str, Any]:
    """The row's columns of one recording (``row`` gets its axis and timing as soon as they
    are known, so that an error row has them too); raises on unusable input."""
    from ..bagio import list_axes
    from ..core.plantfit.physical import check_identifiable

    namespace, joint, axis = which
    min_duration_s, alpha, min_share, max_samples = numbers
    sim, sim_namespace, sim_sha256 = reference
    if namespace is None and joint is None:
        axes = list_axes(path)
        namespace, joint = axes[0] if len(axes) == 1 else (None, None)
    row.update(axis=axis or joint or namespace, namespace=namespace, joint=joint)
    opts = _options(alpha, min_share, max_samples)
    ex = _read(path, namespace, joint, opts, "recording")
    fs = ex.joined.sample_rate_hz
    row.update(start_time=float(ex.joined.t[0]), duration_s=ex.total / fs, sample_rate_hz=fs,
               samples=ex.used, speed_derived=bool(ex.joined.speed_derived))
    if ex.total / fs < min_duration_s:
        raise PmsmSysidError(f"{path}: too short: {ex.total / fs:.3g} s of data (the fleet "
                             f"needs at least {min_duration_s:g} s per recording)")
    check_identifiable(ex.parts, f"recording {path}")
    if plant is not None:
        return _fit_and_diagnose(ex, plant, opts)
    return _against_sim(ex, os.fspath(sim or ""), sim_namespace, sim_sha256, opts)
