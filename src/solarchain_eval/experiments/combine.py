"""Combined per-setting files of a paper root: the eval units' tables concatenated.

``ROOT/combined/<setting>/`` gets ``metrics.csv``, ``actions.csv``, ``city_hour_policy.csv``
(and ``agentic_logs.jsonl`` and ``governance_diagnostics.csv`` where the units have them), the units in the grid's order (policy
order of the setting, then seed), plus ``summary.json``. Files with identical headers are
concatenated as text, so every value keeps its exact bytes; otherwise (e.g. extra columns in
some units) the union of columns is written by pandas with round-trip float parsing.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from ..common.atomic_files import atomic_write_json, atomic_write_with, read_csv_exact
from ..evaluation.records import ACTIONS_FILE, CITY_HOUR_FILE, DIAGNOSTICS_FILE, METRICS_FILE, SUMMARY_FILE, summarize
from .layout import AGENTIC_LOG_FILE, combined_dir

TABLES = (METRICS_FILE, ACTIONS_FILE, CITY_HOUR_FILE)


def concat_csv(sources: Sequence[Path], target: Path) -> int:
    """Concatenate CSV files (header once) into ``target`` atomically; returns the data rows."""
    headers = []
    for path in sources:
        with open(path, encoding="utf-8") as handle:
            headers.append(handle.readline())
    if len(set(headers)) <= 1:
        rows = [0]

        def write(tmp: Path) -> None:
            with open(tmp, "w", encoding="utf-8", newline="") as out:
                out.write(headers[0] if headers else "\n")
                for path in sources:
                    with open(path, encoding="utf-8", newline="") as handle:
                        handle.readline()
                        for line in handle:
                            out.write(line if line.endswith("\n") else line + "\n")
                            rows[0] += 1

        atomic_write_with(target, write)
        return rows[0]
    frame = pd.concat([read_csv_exact(p) for p in sources], ignore_index=True)
    atomic_write_with(target, lambda tmp: frame.to_csv(tmp, index=False))
    return len(frame)


def concat_lines(sources: Sequence[Path], target: Path) -> int:
    count = [0]

    def write(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8") as out:
            for path in sources:
                with open(path, encoding="utf-8") as handle:
                    for line in handle:
                        if line.strip():
                            out.write(line if line.endswith("\n") else line + "\n")
                            count[0] += 1

    atomic_write_with(target, write)
    return count[0]


def combine_setting(root: Path, setting: str, unit_dirs: Sequence[Path]) -> dict[str, int]:
    """Write the combined files of one setting from its eval units; returns rows per file."""
    out = combined_dir(root, setting)
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, int] = {}
    for name in TABLES:
        missing = [str(d / name) for d in unit_dirs if not (d / name).is_file()]
        if name == CITY_HOUR_FILE and len(missing) == len(unit_dirs):
            # a task that records no per-step extras writes no such table (Task.step_extra_names)
            (out / name).unlink(missing_ok=True)
            continue
        if missing:
            raise FileNotFoundError(f"cannot combine setting '{setting}': {missing[0]} is missing")
        rows[name] = concat_csv([d / name for d in unit_dirs], out / name)
    logs = [d / AGENTIC_LOG_FILE for d in unit_dirs if (d / AGENTIC_LOG_FILE).is_file()]
    if logs:
        rows[AGENTIC_LOG_FILE] = concat_lines(logs, out / AGENTIC_LOG_FILE)
    else:
        (out / AGENTIC_LOG_FILE).unlink(missing_ok=True)
    diagnostics = [d / DIAGNOSTICS_FILE for d in unit_dirs if (d / DIAGNOSTICS_FILE).is_file()]
    if diagnostics:
        rows[DIAGNOSTICS_FILE] = concat_csv(diagnostics, out / DIAGNOSTICS_FILE)
    else:
        (out / DIAGNOSTICS_FILE).unlink(missing_ok=True)
    metrics = read_csv_exact(out / METRICS_FILE)
    atomic_write_json(out / SUMMARY_FILE, summarize(metrics))
    return rows
