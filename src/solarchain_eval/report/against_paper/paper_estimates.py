"""The run's estimate of a quantity the paper prints: one definition for the value, its interval and
its spread over training seeds.

An :class:`Estimate` is a statistic of weighted rollouts: weights of shape (B, n) give B
estimates. All-ones weights give the run's value; the start-day cluster bootstrap of
:func:`~solarchain_eval.report.statistics.cluster_bootstrap` gives its interval; weights that
redraw each learned policy's training seeds (:mod:`~solarchain_eval.report.against_paper.seed_spread`) give its
spread over trainings. Every estimate keeps ``policy``, ``run_seed``, ``episode_seed`` and
``start_hour`` for its rows, so any of these weightings applies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ...evaluation.settings import setting_is_agentic
from ...tasks.registry import DEFAULT_TASK, get_task
from ..loading import ReportData
from ..naming import llm_record
from ..options import ReportOptions
from ..statistics import Interval, cluster_bootstrap, mean_std, paired_deltas
from .paper_reference import Ref

#: The identity columns every estimate keeps for its rows.
KEYS = ("policy", "run_seed", "episode_seed", "start_hour")
Statistic = Callable[[np.ndarray], np.ndarray]
#: The verdict and the run column of a published number the run has no estimate for.
NOT_IN_RUN = "not in run"


@dataclass(frozen=True)
class Estimate:
    """A statistic of weighted rows.

    Attributes
    ----------
    rows
        The rollouts (or matched pairs) behind the estimate, with the :data:`KEYS` columns.
    statistic
        Maps weights of shape (B, len(rows)) to B estimates.
    """

    rows: pd.DataFrame
    statistic: Statistic

    @property
    def value(self) -> float:
        """The estimate with every row counted once."""
        return float(np.asarray(self.statistic(np.ones((1, len(self.rows)))))[0])

    def interval(self, options: ReportOptions) -> Interval:
        """The estimate with its cluster-bootstrap interval (clusters: ``options.cluster_by``)."""
        return cluster_bootstrap(self.statistic, self.rows[options.cluster_by].to_numpy(), **options.bootstrap())

    def replicates(self, weights: np.ndarray) -> np.ndarray:
        """B estimates under B weightings of the rows."""
        return np.asarray(self.statistic(np.asarray(weights, dtype=float)), dtype=float)


def _weighted_mean(values: np.ndarray) -> Statistic:
    def statistic(w: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return (w @ values) / w.sum(axis=1)

    return statistic


def difference(a: Estimate, b: Estimate) -> Estimate:
    """``a - b``; its rows are both estimates' rows, so a shared start day is resampled as one."""
    n = len(a.rows)

    def statistic(w: np.ndarray) -> np.ndarray:
        return a.statistic(w[:, :n]) - b.statistic(w[:, n:])

    return Estimate(pd.concat([a.rows[list(KEYS)], b.rows[list(KEYS)]], ignore_index=True), statistic)


class RunEstimates:
    """The run's estimate of each :class:`~solarchain_eval.report.against_paper.paper_reference.Ref`.

    Parameters
    ----------
    metrics
        The run's ``metrics.csv`` rows (all settings).
    """

    def __init__(self, metrics: pd.DataFrame) -> None:
        self.metrics = metrics
        self._settings = {str(s): frame for s, frame in metrics.groupby("setting", sort=False)}
        self._pairs: dict[tuple[str, str], pd.DataFrame] = {}
        self._found: dict[Ref, Estimate | None] = {}

    def _rows(self, setting: str, policies: tuple[str, ...], columns: list[str]) -> pd.DataFrame | None:
        frame = self._settings.get(setting)
        if frame is None or any(c not in frame.columns for c in columns):
            return None
        rows = frame[frame["policy"].isin(policies)]
        if set(rows["policy"]) != set(policies) or rows[columns].isna().all(axis=None):
            return None  # a pooled row needs every policy it pools
        return rows[[*KEYS, *columns]].reset_index(drop=True)

    def get(self, ref: Ref) -> Estimate | None:
        """The estimate of ``ref``; None when the run lacks its rollouts or columns (computed once per ref).

        Statistics: ``mean`` (a paired delta when ``ref.base_setting`` is set) and ``pooled``
        (revisions per audit, pooled over episodes).
        """
        if ref not in self._found:
            self._found[ref] = self._estimate(ref)
        return self._found[ref]

    def _estimate(self, ref: Ref) -> Estimate | None:
        if ref.statistic == "pooled":
            return self._pooled_rate(ref)
        if ref.statistic != "mean":
            raise ValueError(f"no run estimate for statistic {ref.statistic!r}")
        if ref.base_setting is not None:
            return self._paired(ref)
        rows = self._rows(ref.setting, ref.policies, [ref.metric])
        return None if rows is None else Estimate(rows, _weighted_mean(rows[ref.metric].to_numpy(dtype=float)))

    def std(self, ref: Ref) -> float:
        """Sample standard deviation (ddof=1) over the rows of a plain mean (the paper's ± column)."""
        rows = self._rows(ref.setting, ref.policies, [ref.metric])
        return float("nan") if rows is None else mean_std(rows[ref.metric])[1]

    def _pooled_rate(self, ref: Ref) -> Estimate | None:
        rows = self._rows(ref.setting, ref.policies, ["audit_rate", "revision_rate"])
        if rows is None:
            return None
        audits = rows["audit_rate"].to_numpy(dtype=float)
        revisions = rows["revision_rate"].to_numpy(dtype=float) * audits

        def statistic(w: np.ndarray) -> np.ndarray:
            with np.errstate(invalid="ignore", divide="ignore"):
                return (w @ revisions) / (w @ audits)

        return Estimate(rows, statistic)

    def _paired_frame(self, base: str, treated: str) -> pd.DataFrame:
        """Matched ``treated - base`` deltas of every numeric metric column (computed once per pair)."""
        if (base, treated) not in self._pairs:
            both = self.metrics[self.metrics["setting"].isin([base, treated])]
            columns = [
                c
                for c in both.columns
                if c not in (*KEYS, "setting", "episode") and pd.api.types.is_numeric_dtype(both[c])
            ]
            self._pairs[(base, treated)] = paired_deltas(both, base, treated, columns).frame
        return self._pairs[(base, treated)]

    def _paired(self, ref: Ref) -> Estimate | None:
        assert ref.base_setting is not None
        if ref.base_setting not in self._settings or ref.setting not in self._settings:
            return None
        frame = self._paired_frame(ref.base_setting, ref.setting)
        if ref.metric not in frame.columns:
            return None
        frame = frame[frame["policy"].isin(ref.policies)]
        if set(frame["policy"]) != set(ref.policies) or frame[ref.metric].isna().all():
            return None
        frame = frame[[*KEYS, ref.metric]].reset_index(drop=True)
        return Estimate(frame, _weighted_mean(frame[ref.metric].to_numpy(dtype=float)))


def stand_in(data: ReportData) -> str | None:
    """What stands in for the paper's hosted LLM in the run's agentic rows, or None when nothing does.

    E.g. "rule planner, rule auditor" or "local model SmolLM2-135M-Instruct"; a run without the
    ``planner``/``auditor`` columns says "planner/auditor not recorded".
    """
    agentic = data.metrics[data.metrics["setting"].map(setting_is_agentic)]
    if agentic.empty:
        return None
    if not {"planner", "auditor"} <= set(agentic.columns):
        return "planner/auditor not recorded"
    parts = [
        f"{kind} {role}"
        for role in ("planner", "auditor")
        for kind in sorted(set(agentic[role].dropna().astype(str)))
        if kind != "llm"
    ]
    llm = llm_record(data.metadata)
    uses_llm = (agentic[["planner", "auditor"]].astype(str) == "llm").any(axis=None)
    if uses_llm and llm is not None and llm.get("decoding") is not None:
        parts.append(f"local model {llm['model']}")
    return ", ".join(parts) or None


def is_agentic(ref: Ref) -> bool:
    """Whether the quantity involves a setting behind the Planner/Auditor layer."""
    return setting_is_agentic(ref.setting) or (ref.base_setting is not None and setting_is_agentic(ref.base_setting))


def is_deterministic(ref: Ref) -> bool:
    """Rule baselines without the layer: the same data and protocol give the same digits."""
    baselines = get_task(DEFAULT_TASK).baselines()  # the paper's market's
    return all(p in baselines for p in ref.policies) and not is_agentic(ref)


__all__ = [
    "KEYS",
    "NOT_IN_RUN",
    "Estimate",
    "RunEstimates",
    "difference",
    "is_agentic",
    "is_deterministic",
    "stand_in",
]
