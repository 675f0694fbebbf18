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

if TYPE_CHECKING:
    from ..core.discrepancy.fitted import PlantFitResult
    from ..core.recording.signals import Recording

#: Recordings shorter than this (s) are refused by default: a few seconds of data give
#: parameters too uncertain to follow over time.
MIN_DURATION_S = 5.0


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _fit_and_diagnose(rec: Any, plant: Plant, alpha: float,
                      min_share: float) -> dict[str, Any]:
    """The plant part of the row: the fitted physical plant, and the diagnosis of the
    reference plant on the same recording."""
    from ..core.fleet import diagnosis_columns, plant_columns
    from .diagnosis import diagnose
    from .plantfit import fit_plant

    fit = fit_plant(rec, alpha=alpha, min_share=min_share).to_dict()
    found = diagnose(plant, rec, alpha=alpha, min_share=min_share, replay=False,
                     gfrf=False).to_dict()
    row = plant_columns(fit.get("plant") or {}, fit.get("std") or {}, fit.get("effects") or [])
    row.update(diagnosis_columns(found))
    row["effects"] = [str(e.get("name")) for e in fit.get("effects") or []]
    return row


@functools.lru_cache(maxsize=4)
def _sim_fit(path: str, namespace: str | None, alpha: float, min_share: float,
             content: str | None) -> tuple[Recording, PlantFitResult]:
    """The simulator's recording and its fitted plant, once per process (a worker analysing
    many recordings against one simulation fits it once; ``content`` keys the cache to the
    file's content)."""
    from ..core.discrepancy.fitted import fit_plant
    from ..core.plantfit.fit import FitOptions
    from .diagnosis import _recording

    rec = _recording(path, "sim", namespace)
    return rec, fit_plant(rec, None, FitOptions(alpha=alpha, min_share=min_share))


def _against_sim(rec: Recording, sim: str, sim_namespace: str | None, sim_content: str | None,
                 alpha: float, min_share: float) -> dict[str, Any]:
    """The plant part of the row with a simulator's recording as the reference: the real
    recording's fitted plant (fitted once, inside the comparison) and the comparison."""
    from ..core.discrepancy import DiagnoseOptions
    from ..core.discrepancy.against import diagnose_sim
    from ..core.fleet import diagnosis_columns, plant_columns

    sim_rec, sim_fit = _sim_fit(sim, sim_namespace, alpha, min_share, sim_content)
    options = DiagnoseOptions(alpha=alpha, min_share=min_share, replay=False, gfrf=False)
    found = diagnose_sim(sim_rec, rec, None, options, sim_fit=sim_fit).to_dict()
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
                  min_share: float = 0.01, sim: str | os.PathLike[str] | None = None,
                  sim_namespace: str | None = None,
                  sim_sha256: str | None = None) -> dict[str, Any]:
    """Analyse one axis of one recording into one row of the fleet table.

    Reads the recording (``namespace``: its topic namespace or JointState topic; ``joint``:
    the JointState joint; None finds the one axis), fits its physical plant
    (:func:`pmsm_sysid.fit_plant`) and diagnoses the reference on it
    (:func:`pmsm_sysid.diagnose`, equation error only: no replay, no GFRF comparison). The
    reference is ``plant``, or ``sim``, a recording of the user's simulator (read with
    ``sim_namespace``; fitted once per process, ``sim_sha256`` its content key).
    ``axis`` names the row's axis (default: the namespace or the joint). Returns the row as
    a dict of the fleet table's columns (:func:`pmsm_sysid.core.fleet.columns`); times in s
    since 1970 (UTC).
    """
    if (plant is None) == (sim is None):
        raise OptionError("give the reference as a plant or as a simulator's recording "
                          "(sim=), one of the two")
    from ..bagio import list_axes, read_recording
    from ..core.fleet import empty_row
    from ..core.selection.datacheck import check_sampling

    started = time.perf_counter()
    row = empty_row()
    row.update(recording=str(path), status="error", content_sha256=content_sha256)
    try:
        if namespace is None and joint is None:
            axes = list_axes(Path(path))
            namespace, joint = axes[0] if len(axes) == 1 else (None, None)
        row.update(axis=axis or joint or namespace, namespace=namespace, joint=joint)
        rec = read_recording(Path(path), namespace=namespace, joint_name=joint).recording
        fs = rec.sample_rate_hz
        row.update(start_time=float(rec.t[0]), duration_s=len(rec) / fs, sample_rate_hz=fs,
                   samples=len(rec), speed_derived=bool(rec.speed_derived))
        if len(rec) / fs < min_duration_s:
            raise PmsmSysidError(f"{path}: too short: {len(rec) / fs:.3g} s of data (the "
                                 f"fleet needs at least {min_duration_s:g} s per recording)")
        check_sampling(rec.t, fs, f"recording {path}")
        if plant is not None:
            row.update(_fit_and_diagnose(rec, plant, alpha, min_share))
        else:
            row.update(_against_sim(rec, os.fspath(sim or ""), sim_namespace, sim_sha256,
                                    alpha, min_share))
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

