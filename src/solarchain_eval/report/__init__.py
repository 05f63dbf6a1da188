"""The report: every table and figure of the paper regenerated from a run, with honest statistics.

``build_report(root)`` reads a run directory or a paper root (see
:mod:`solarchain_eval.experiments.layout`) and writes ``root/report/``: ``tables/<key>.{md,tex,csv}``,
``figures/<key>.{png,svg}``, ``report.md`` and a self-contained ``index.html``.
"""

from __future__ import annotations

from .build import FORMATS, ReportOutcome, build_report, parse_formats
from .loading import ReportData, ReportDataError, load_report_data
from .options import ReportOptions

__all__ = [
    "FORMATS",
    "ReportData",
    "ReportDataError",
    "ReportOptions",
    "ReportOutcome",
    "build_report",
    "load_report_data",
    "parse_formats",
]
