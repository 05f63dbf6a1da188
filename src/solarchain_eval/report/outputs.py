"""What a report writes and returns, shared by the run's report (:mod:`.paper.build`) and a suite
root's (:mod:`.suite_report`): the outcome, the table writers and the page names.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..common.atomic_files import atomic_write_text
from .figure_style import FigureFile
from .loading import ReportData
from .suite_loading import SuiteData
from .table_model import ReportTable, Skipped, to_csv, to_latex, to_markdown

TABLE_FORMATS = {"md": to_markdown, "tex": to_latex, "csv": to_csv}
INDEX_FILE = "index.html"
MARKDOWN_FILE = "report.md"


@dataclass
class ReportOutcome:
    """What :func:`~.paper.build.build_report` made: output folder, tables and figures (or why not), files, warnings.

    ``data`` is the run's :class:`~.loading.ReportData`, or a suite root's :class:`~.suite_loading.SuiteData`."""

    out_dir: Path
    data: ReportData | SuiteData
    tables: list[ReportTable | Skipped]
    figures: list[FigureFile | Skipped]
    files: list[Path] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    #: The against-paper tables (``build_report(against="paper")``), else empty.
    against: list[ReportTable | Skipped] = field(default_factory=list)


def write_tables(out_dir: Path, tables: Sequence[ReportTable | Skipped], formats: Sequence[str]) -> list[Path]:
    """Write each made table as ``tables/<key>.<format>`` (atomically) for the table formats among ``formats``."""
    return [
        atomic_write_text(out_dir / "tables" / f"{table.key}.{fmt}", TABLE_FORMATS[fmt](table))
        for table in tables
        if isinstance(table, ReportTable)
        for fmt in formats
        if fmt in TABLE_FORMATS
    ]
