"""Frequency-domain analysis of an identified model: :func:`gfrf`."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import DataError, GfrfError, IdentificationError, OptionError
from ..core.frequency.analysis import MAX_REPORT_GRID, GfrfAnalysis
from .identification import Identification

ModelLike = Identification | Mapping[str, Any] | str | os.PathLike[str]
MAX_ORDER = 4


def _model_json(model: ModelLike) -> tuple[dict[str, Any], str]:
    """The identify JSON of ``model`` and a label for messages."""
    if isinstance(model, Identification):
        # through JSON text, exactly as the CLI reads the file identify wrote
        return json.loads(json.dumps(model.to_dict(), allow_nan=False)), "model"
    if isinstance(model, (str, os.PathLike)):
        from ..validate import read_json_object

        d: Any = read_json_object(str(Path(model)), "a model JSON written by identify")
        label = str(model)
    elif isinstance(model, Mapping):
        d, label = dict(model), "model"
    else:
        raise OptionError(f"model must be an Identification, an identify JSON dict or its "
                          f"path, got {type(model).__name__}")
    if isinstance(d, dict) and "terms" not in d and isinstance(d.get("last_model"), dict):
        d = d["last_model"]  # a run summary: its last speed model
    if not isinstance(d, dict) or "terms" not in d:
        raise GfrfError(f"{label}: not a model JSON (no 'terms'; expected the output of "
                        "identify)")
    return d, label


def _points(at: Iterable[Sequence[float]]) -> list[tuple[float, ...]]:
    out = []
    for point in at:
        try:
            values = tuple(float(x) for x in point)
        except (TypeError, ValueError) as exc:
            raise OptionError(f"at: each point is a sequence of 1 to {MAX_ORDER} numbers, "
                              f"got {point!r}") from exc
        if not 1 <= len(values) <= MAX_ORDER:
            raise OptionError(f"at: 1 to {MAX_ORDER} frequencies per point, got {point!r}")
        if any(not math.isfinite(v) or abs(v) > 0.5 for v in values):
            raise OptionError("at: normalised frequencies must be finite and within "
                              f"[-0.5, 0.5] (cycles/sample), got {point!r}")
        out.append(values)
    return out


def _check(grid: int | None, orders: Iterable[int]) -> tuple[int, ...]:
    if grid is not None and (isinstance(grid, bool) or not isinstance(grid, int)
                             or not 2 <= grid <= MAX_REPORT_GRID):
        raise OptionError(f"grid must be 2..{MAX_REPORT_GRID} points per axis, got {grid!r}")
    chosen = tuple(sorted(set(orders)))
    if not chosen or any(o not in (1, 2, 3) for o in chosen):
        raise OptionError(f"orders are among 1, 2, 3, got {orders!r}")
    return chosen


def gfrf(model: ModelLike, *, at: Iterable[Sequence[float]] = (), grid: int | None = None,
         orders: Iterable[int] = (1, 2, 3)) -> GfrfAnalysis:
    """Generalized frequency response functions of an identified NARX model: poles, H1
    peaks, H2 and H3 ridges, each marked supported or not by the excitation of the
    estimation data.

    ``model``: the :class:`Identification` from :func:`identify`, or an identify JSON (a
    dict, or the path of the file ``pmsm-sysid identify --json`` wrote; a run summary's
    last model is used). Options as ``pmsm-sysid gfrf``: ``at`` evaluates the symmetric H_n
    at points of 1-4 normalised frequencies (cycles/sample, within +-0.5); ``grid=N`` adds
    H1 and the H2/H3 magnitudes on N-point grids; ``orders`` chooses which GFRFs to search.

    Returns a :class:`GfrfAnalysis`; its ``to_dict()`` is the gfrf JSON.

    Example:
        >>> import pmsm_sysid as ps
        >>> fit = ps.identify("bags/paper_speed_nominal")
        >>> res = ps.gfrf(fit, at=[(0.033,)])
        >>> peak = res.to_dict()["h1"]["peaks"][0]
        >>> peak["kind"], round(peak["freq_hz"], 1), res.stable
        ('resonance', 16.5, True)
        >>> res.to_dict()["eval"][0]["order"]
        1
    """
    from ..core.frequency.analysis import analyse_json

    points = _points(at)
    chosen = _check(grid, orders)
    d, label = _model_json(model)
    try:
        return analyse_json(d, at=points, grid=grid, orders=chosen)
    except IdentificationError as exc:
        raise GfrfError(f"{label}: {exc}") from exc
    except DataError as exc:
        raise GfrfError(f"{label}: bad 'excitation' block: {exc}") from exc
