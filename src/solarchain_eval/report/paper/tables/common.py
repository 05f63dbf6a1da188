"""Helpers shared by the table builders: group summaries and the columns they need."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd

from ....records_schema import AGENTIC_NUMERIC_NAMES
from ...loading import ReportData
from ...naming import is_learned
from ...statistics import SampleSize, mean_std, sample_size

#: Columns a table must find in ``metrics.csv`` rows of an agentic setting (the agentic contract,
#: defined in :mod:`solarchain_eval.records_schema`).
AGENTIC_COLUMNS = AGENTIC_NUMERIC_NAMES


def size_fields(frame: pd.DataFrame) -> dict[str, int]:
    """``n``, ``distinct_episode_seeds`` and ``distinct_start_days`` of ``frame`` (CSV columns)."""
    size = sample_size(frame)
    return {"n": size.n, "distinct_episode_seeds": size.episode_seeds, "distinct_start_days": size.start_days}


def sizes_of(data: pd.DataFrame) -> list[SampleSize]:
    """The :class:`SampleSize` of each table row from its size fields."""
    return [
        SampleSize(int(r["n"]), int(r["distinct_episode_seeds"]), int(r["distinct_start_days"]))
        for r in data.to_dict("records")
    ]


def moments(frame: pd.DataFrame, columns: Iterable[str], *, extremes: bool = False) -> dict[str, float]:
    """``<col>_mean`` and ``<col>_std`` (ddof=1) per column, plus ``_min``/``_max`` if asked."""
    out: dict[str, float] = {}
    for column in columns:
        values = frame[column].to_numpy(dtype=float)
        out[f"{column}_mean"], out[f"{column}_std"] = mean_std(values)
        if extremes:
            out[f"{column}_min"] = float(values.min())
            out[f"{column}_max"] = float(values.max())
    return out


def means(frame: pd.DataFrame, columns: Iterable[str]) -> dict[str, float]:
    """Plain means per column."""
    return {column: float(frame[column].to_numpy(dtype=float).mean()) for column in columns}


def learned_rollouts(data: ReportData) -> pd.DataFrame:
    """Metrics rows of learned policies in every setting."""
    return data.metrics[data.metrics["policy"].map(is_learned)]


def missing_columns(frame: pd.DataFrame, columns: Sequence[str]) -> list[str]:
    """Columns absent from ``frame`` or entirely empty in it."""
    return [c for c in columns if c not in frame.columns or frame[c].isna().all()]


def agentic_rollouts(data: ReportData, settings: Sequence[str]) -> tuple[pd.DataFrame, list[str]]:
    """Rows of ``settings`` and the agentic columns they lack (empty list when complete)."""
    frame = data.metrics[data.metrics["setting"].isin(settings)]
    if frame.empty:
        return frame, []
    return frame, missing_columns(frame, AGENTIC_COLUMNS)


def pooled_revision_rate(frame: pd.DataFrame) -> float:
    """Revisions per audit pooled over episodes: Σ revision_rate·audit_rate / Σ audit_rate.

    Per episode, revision_rate = revisions / max(audits, 1) and audit_rate = audits / steps,
    so this is total revisions / total audits over the group (all episodes have the same length).
    """
    audits = frame["audit_rate"].to_numpy(dtype=float)
    total = audits.sum()
    return float((frame["revision_rate"].to_numpy(dtype=float) * audits).sum() / total) if total > 0 else float("nan")


def percentile_fields(values: np.ndarray, name: str) -> dict[str, float]:
    """Mean and 5th/95th percentiles (numpy's linear interpolation) of ``values``."""
    return {
        f"{name}_mean": float(values.mean()),
        f"{name}_p05": float(np.percentile(values, 5)),
        f"{name}_p95": float(np.percentile(values, 95)),
    }
