"""Build the API reference (HTML) from the docstrings with pdoc: ``make docs``.

Documents the public names of ``import pmsm_sysid as ps`` (its ``__all__``) on one page,
plus the API modules they come from. Usage: ``python scripts/api_docs.py [OUT_DIR]``
(default docs/api).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pdoc
import pdoc.render

import pmsm_sysid

MODULES = ["pmsm_sysid"]


def build(out: Path) -> Path:
    """Write the HTML pages into ``out``; return the index page."""
    for name in pmsm_sysid.__all__:  # load the lazily imported public names for pdoc
        getattr(pmsm_sysid, name)
    pdoc.render.configure(docformat="google", footer_text="pmsm_sysid API reference",
                          search=True, show_source=False)
    pdoc.pdoc(*MODULES, output_directory=out)
    return out / "pmsm_sysid.html"


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/api")
    index = build(target)
    print(f"API reference: {index}")
