"""On-disk layout of runs: a single ``evaluate`` run directory, and a ``paper`` root.

A single run directory (``solarchain-eval evaluate --out RUN_DIR``)::

    RUN_DIR/metrics.csv  actions.csv  city_hour_policy.csv  summary.json  run_metadata.json
           [agentic_logs.jsonl]            (agentic settings only)

A paper root (``solarchain-eval paper --out ROOT``)::

    ROOT/paper_metadata.json                            the grid spec, versions, dataset provenance
    ROOT/units/train/<algo>-<setting>-<seed>/           one trained model (SB3 .zip, config, log)
    ROOT/units/train/<algo>-<setting>-<s1>+<s2>+.../    JAX backend: a seed group, seed_<s>/ per model
    ROOT/units/eval/<policy>-<setting>-<seed>/          one evaluation = a run directory (policy: a built-in or user agent name)
    ROOT/combined/<setting>/metrics.csv ...             every unit of a setting concatenated
    ROOT/report/                                        tables, figures, index.html

Every unit directory gets the done-marker ``DONE`` written last; a unit without it is redone.
``setting`` is one of :data:`~solarchain_eval.evaluation.rollout.SETTINGS`.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..evaluation.records import ACTIONS_FILE, AGENTIC_LOG_FILE, CITY_HOUR_FILE, METADATA_FILE, METRICS_FILE
from ..evaluation.records import REPORT_DIR as RUN_REPORT_DIR

DONE_MARKER = "DONE"
PAPER_METADATA_FILE = "paper_metadata.json"
UNITS_DIR = "units"
COMBINED_DIR = "combined"
REPORT_DIR = RUN_REPORT_DIR  # the report of a paper root, as of a run directory


def train_unit_dir(root: Path, algo: str, setting: str, seed: int | str) -> Path:
    """``seed`` is a seed, or a seed group's label (``<seed>+<seed>+...``, JAX backend)."""
    return Path(root) / UNITS_DIR / "train" / f"{algo}-{setting}-{seed}"


def seed_model_dir(train_dir: Path, seed: int) -> Path:
    """Where a seed group's train unit (JAX backend) keeps the model of ``seed``."""
    return Path(train_dir) / f"seed_{seed}"


def eval_unit_dir(root: Path, policy: str, setting: str, seed: int) -> Path:
    return Path(root) / UNITS_DIR / "eval" / f"{policy}-{setting}-{seed}"


def eval_unit_dirs(root: Path) -> list[Path]:
    """The eval unit directories of a paper root, finished or not, in name order."""
    units = Path(root) / UNITS_DIR / "eval"
    if not units.is_dir():
        return []
    # Dot-names are staging folders and locks of run directories being written.
    return [unit for unit in sorted(units.iterdir()) if unit.is_dir() and not unit.name.startswith(".")]


def combined_dir(root: Path, setting: str) -> Path:
    return Path(root) / COMBINED_DIR / setting


def is_done(unit_dir: Path) -> bool:
    return (Path(unit_dir) / DONE_MARKER).is_file()


def is_paper_root(root: Path) -> bool:
    return (Path(root) / COMBINED_DIR).is_dir() or (Path(root) / PAPER_METADATA_FILE).is_file()


def run_table_paths(root: Path, name: str) -> list[Path]:
    """The files holding table ``name`` (e.g. ``metrics.csv``) of a run dir or paper root."""
    root = Path(root)
    if is_paper_root(root):
        return sorted((root / COMBINED_DIR).glob(f"*/{name}"))
    path = root / name
    return [path] if path.is_file() else []


def read_run_table(root: Path, name: str = METRICS_FILE) -> pd.DataFrame:
    """Concatenate table ``name`` over a run dir or a paper root's settings (empty if absent)."""
    paths = run_table_paths(root, name)
    if not paths:
        return pd.DataFrame()
    return pd.concat([pd.read_csv(path) for path in paths], ignore_index=True)


__all__ = [
    "ACTIONS_FILE",
    "CITY_HOUR_FILE",
    "METADATA_FILE",
    "METRICS_FILE",
    "AGENTIC_LOG_FILE",
    "DONE_MARKER",
    "PAPER_METADATA_FILE",
    "train_unit_dir",
    "seed_model_dir",
    "eval_unit_dir",
    "eval_unit_dirs",
    "combined_dir",
    "is_done",
    "is_paper_root",
    "run_table_paths",
    "read_run_table",
]
