"""Offline NARX identification: :func:`identify` and its result :class:`Identification`."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.errors import OptionError
from ..core.recording.signals import Recording
from ..core.selection.identify import FORMS, FitConfig, IdentifyResult
from ..core.selection.ofr import CRITERIA
from ..core.terms.model import NarxModel, Structure
from . import _checks
from ._json import plain

if TYPE_CHECKING:
    from ..core.recording.align import AlignReport

DataLike = Recording | str | os.PathLike[str]
OUTPUTS = ("speed", "position")
METHODS = ("iofr", "ofr")


@dataclass(frozen=True)
class Identification:
    """The result of :func:`identify`: the fitted model, its validation and where the data
    came from. :meth:`to_dict` is the JSON that ``pmsm-sysid identify --json`` writes.

    Example:
        >>> import json, pmsm_sysid as ps
        >>> fit = ps.identify("bags/paper_speed_nominal", validate=None)
        >>> fit.model.output_name, fit.to_dict()["validate"] is None
        ('speed', True)
        >>> text = json.dumps(fit.to_dict())  # plain data: ready for JSON
    """

    result: IdentifyResult
    """Everything the fit produced (terms, ERR, validation, data checks, timings)."""
    source: str | None = None
    """Absolute path of the recording read (None when a Recording was passed)."""
    alignment: AlignReport | None = None
    """How the bag's streams were aligned (None when a Recording was passed)."""

    @property
    def model(self) -> NarxModel:
        """The identified polynomial NARX model (terms and estimates)."""
        return self.result.model

    def to_dict(self) -> dict[str, Any]:
        """The identify JSON as plain Python data (non-finite numbers as None)."""
        d = self.result.to_dict()
        if self.source is not None:
            d["source"] = self.source
        if self.alignment is not None:
            d["alignment"] = self.alignment.to_dict()
        out: dict[str, Any] = plain(d)
        return out


def fit_config(*, ny: int = 30, nu: int = 40, degree: int = 2, terms: int = 15,
               delay: int = 1, criterion: str = "terms", rho: float = 1e-3,
               method: str = "iofr", constant: bool = True, keep_dc: bool = False) -> FitConfig:
    """The identification settings of :func:`identify`'s options, each checked."""
    structure = Structure(ny=_checks.count("ny", ny), nu=_checks.count("nu", nu),
                          degree=_checks.choice("degree", degree, (1, 2, 3)),
                          delay=_checks.count("delay", delay), constant=bool(constant))
    return FitConfig(structure=structure, n_terms=_checks.count("terms", terms, 1),
                     criterion=_checks.choice("criterion", criterion, CRITERIA),
                     rho=_checks.fraction("rho", rho),
                     method=_checks.choice("method", method, METHODS),
                     remove_dc=not keep_dc)


def identify(data: DataLike, *, output: str = "speed", input: str = "thrust",
             ny: int = 30, nu: int = 40, degree: int = 2, terms: int = 15, delay: int = 1,
             estimate: tuple[int, int] = (1000, 2000),
             validate: tuple[int, int] | None = (3000, 4000),
             criterion: str = "terms", rho: float = 1e-3, method: str = "iofr",
             constant: bool = True, keep_dc: bool = False, corr_lags: int = 20,
             namespace: str | None = None, form: str = "level",
             joint: str | None = None) -> Identification:
    """Identify a polynomial NARX model of ``output`` driven by thrust, by orthogonal forward
    regression (error reduction ratio), and validate it.

    ``data``: a rosbag2 path (read with :func:`read_bag`, ``namespace`` and ``joint`` as
    there) or a
    :class:`Recording`. The options are those of ``pmsm-sysid identify``: ``ny``/``nu``
    output and input lags, ``degree`` (1-3), ``terms`` (the number, or the maximum for
    ``criterion`` ``err``/``aic``/``bic``), input ``delay``, ``estimate`` and ``validate``
    sample ranges (0-based, half-open; ``validate=None`` skips validation), ``rho`` (ERR
    tolerance for ``criterion="err"``), ``method`` (``iofr``: forward regression refined
    by term exchange; ``ofr``: classic forward regression), ``constant=False`` (no constant
    candidate), ``keep_dc`` (ERR on the raw output), ``corr_lags`` (lags of the correlation
    tests), ``form`` (``level``: the output as measured; ``difference``: its increment per
    sample, the bounded form of an integrating output such as position). Defaults reproduce
    the speed case of Liu et al.; ``output="position", ny=10, nu=10`` their position case.

    Every option is checked before any work starts; a bad one raises a
    :class:`PmsmSysidError` saying which.

    Example:
        >>> import pmsm_sysid as ps
        >>> fit = ps.identify("bags/paper_speed_nominal")
        >>> d = fit.to_dict()  # the identify JSON
        >>> len(d["terms"]), "u(k-1)" in fit.model.term_names
        (16, True)
        >>> d["validation"]["validation"]["r2"] > 0.99
        True
    """
    from ..core.selection.identify import identify_recording

    _checks.choice("output", output, OUTPUTS)
    _checks.choice("input", input, ("thrust",))
    _checks.choice("form", form, FORMS)
    config = fit_config(ny=ny, nu=nu, degree=degree, terms=terms, delay=delay,
                        criterion=criterion, rho=rho, method=method, constant=constant,
                        keep_dc=keep_dc)
    est = _checks.sample_range("estimate", estimate)
    val = None if validate is None else _checks.sample_range("validate", validate)
    lags = _checks.count("corr_lags", corr_lags, 1)
    source = alignment = None
    if isinstance(data, Recording):
        rec = data
    elif isinstance(data, (str, os.PathLike)):
        from ..bagio.read import check_ranges_finite
        from .recordings import load_bag

        ranges = {"estimation": est, **({"validation": val} if val is not None else {})}
        # read only as far as the ranges need: a short window of a long recording stays cheap
        loaded = load_bag(data, namespace, until_sample=max(r[1] for r in ranges.values()),
                          joint=joint)
        check_ranges_finite(loaded, ranges, config.structure.max_lag)
        rec, alignment = loaded.recording, loaded.report
        source = str(Path(data).resolve())
    else:
        raise OptionError(f"data must be a Recording or a bag path, got {type(data).__name__}")
    result = identify_recording(rec, input=input, output=output, config=config, estimate=est,
                                validate=val, max_lag_corr=lags, form=form)
    return Identification(result, source, alignment)
