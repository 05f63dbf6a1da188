"""Dataset errors (no heavy imports, so the CLI can catch them without loading pandas)."""

from __future__ import annotations

from pathlib import Path

from ..common.errors import InputDataError


class DatasetError(InputDataError, ValueError):
    """A dataset directory is missing a file or holds invalid data."""

    def __init__(self, path: Path | str, message: str, column: str | None = None, row: int | None = None):
        self.path, self.column, self.row = Path(path), column, row
        where = str(self.path)
        if column is not None:
            where += f", column '{column}'"
        if row is not None:
            where += f", row {row + 1} (line {row + 2})"
        super().__init__(f"{where}: {message}")
