"""The report: every table and figure of the paper regenerated from a run, with honest statistics.

``build_report(root)`` reads a run directory or a paper root (see
:mod:`solarchain_eval.experiments.layout`) and writes ``root/report/``: ``tables/<key>.{md,tex,csv}``,
``figures/<key>.{png,svg}``, ``report.md`` and a self-contained ``index.html``.

One sub-package per concern: :mod:`.paper` (the paper's tables, figures and page),
:mod:`.against_paper` (a run checked against the paper's published values and findings),
:mod:`.leaderboard` (runs of one protocol ranked) and :mod:`.governance` (audit quality and the
governance leaderboard). Shared by them at this level: options, loading, naming, statistics, the
table model and the figure style; :mod:`.compare` and :mod:`.sensitivity` are the reports of the
``compare`` and ``sweep`` commands.

The names below load their modules on first use (PEP 562), so importing a light submodule
(:mod:`.options`) does not pull in pandas, scipy and matplotlib.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..common.lazy import lazy_getattr

#: Public name -> the submodule that defines it.
_EXPORTS = {
    "FORMATS": "options",
    "ReportDataError": "options",
    "ReportOptions": "options",
    "parse_formats": "options",
    "ReportData": "loading",
    "load_report_data": "loading",
    "ReportOutcome": "paper.build",
    "build_report": "paper.build",
}

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

if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ resolves them
    from .loading import ReportData, load_report_data
    from .options import FORMATS, ReportDataError, ReportOptions, parse_formats
    from .paper.build import ReportOutcome, build_report


__getattr__ = lazy_getattr(__name__, _EXPORTS, globals())
