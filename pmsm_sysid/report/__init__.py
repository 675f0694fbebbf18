"""HTML reports: figures (PNG beside ``index.html``) and tables of an identification, its
GFRFs, or a diagnosis. Entry point :func:`build_report`; the page itself is written by
:func:`.html.write_page` from :class:`.html.Section` blocks, so other tools can add pages."""

from __future__ import annotations

from .build import ReportOptions, ReportResult, build_report, report_bag, report_json

__all__ = ["ReportOptions", "ReportResult", "build_report", "report_bag", "report_json"]
