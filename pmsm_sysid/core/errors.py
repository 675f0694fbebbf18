"""Error types, one per area. The CLI turns any :class:`PmsmSysidError` into one line and exit 2."""

from __future__ import annotations


class PmsmSysidError(Exception):
    """Base of every error the project raises on bad input or an impossible request.

    Example:
        >>> import pmsm_sysid as ps
        >>> try:
        ...     ps.identify("no/such/bag")
        ... except ps.PmsmSysidError as exc:
        ...     print("bad input:", exc)  # doctest: +ELLIPSIS
        bad input: no/such/bag: ...
    """


class PlantError(PmsmSysidError):
    """A plant file or plant parameters are invalid."""


class ExcitationError(PmsmSysidError):
    """An excitation signal cannot be generated as asked."""


class DataError(PmsmSysidError):
    """Signals are unusable: NaN/Inf, gaps, wrong lengths, ranges outside the recording."""


class InsufficientExcitationError(DataError):
    """The data do not excite the system enough to identify the requested model."""


class IdentificationError(PmsmSysidError):
    """Structure selection or estimation failed (e.g. rank-deficient candidate set)."""


class GfrfError(PmsmSysidError):
    """A model cannot be mapped to GFRFs as asked (bad model, bad frequencies, grid too big)."""


class DiagnoseError(PmsmSysidError):
    """The sim-to-real diagnosis cannot run on the given plant and recording."""


class BagError(PmsmSysidError):
    """A recording cannot be read or written (missing, corrupt, unknown storage, wrong types)."""


class OutputError(PmsmSysidError):
    """An output path cannot be written: missing directory, a directory where a file is
    expected, an existing result without ``--force``, no permission."""


#: Former name of :class:`PmsmSysidError`, kept so older code that catches it still works.
SysIdError = PmsmSysidError


class DependencyError(PmsmSysidError):
    """An optional part of the package is asked for and its extra is not installed."""


class OptionError(PmsmSysidError):
    """An option has a value outside its documented range (checked before any work starts)."""
