"""The nodes a pipeline can hold, by name (light: no ROS import, so a verb can check its
``--nodes`` before it loads the middleware)."""

from __future__ import annotations

from collections.abc import Sequence

from .core.errors import PmsmSysidError

NODES = ("sim", "identifier", "gfrf", "diagnose")
DEFAULT_NODES = ("sim", "identifier", "gfrf")  # the diagnosis needs a reference: added on demand
#: The nodes whose work runs in worker processes of their own.
WORKER_NODES = ("identifier", "gfrf", "diagnose")


def parse_nodes(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"sim,identifier"`` -> ("sim", "identifier"); PmsmSysidError on unknown or empty."""
    items = [s.strip() for s in (text.split(",") if isinstance(text, str) else text)]
    items = [s for s in items if s]
    bad = [s for s in items if s not in NODES]
    if bad or not items:
        raise PmsmSysidError(f"--nodes takes a comma list of {', '.join(NODES)} (got "
                             f"'{','.join(items) if not bad else ','.join(bad)}')")
    return tuple(dict.fromkeys(items))


__all__ = ["DEFAULT_NODES", "NODES", "WORKER_NODES", "parse_nodes"]
