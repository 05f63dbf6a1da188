"""The run's estimate of a quantity the paper prints: one definition for the value, its interval and
its spread over training seeds.

An :class:`Estimate` is a statistic of weighted rollouts: weights of shape (B, n) give B
estimates. All-ones weights give the run's value; the start-day cluster bootstrap of
:func:`~solarchain_eval.report.statistics.cluster_bootstrap` gives its interval; weights that
redraw each learned policy's training seeds (:mod:`~solarchain_eval.report.seed_spread`) give its
spread over trainings. Every estimate keeps ``policy``, ``run_seed``, ``episode_seed`` and
``start_hour`` for its rows, so any of these weightings applies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .options import ReportOptions
from .paper_reference import Ref
from .statistics import Interval, cluster_bootstrap, mean_std, paired_deltas

#: The identity columns every estimate keeps for its rows.
KEYS = ("policy", "run_seed", "episode_seed", "start_hour")
Statistic = Callable[[np.ndarray], np.ndarray]


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
    """The run's estimate of each :class:`~solarchain_eval.report.paper_reference.Ref`.

    Parameters
    ----------
    metrics
        The run's ``metrics.csv`` rows (all settings).
    """

    def __init__(self, metrics: pd.DataFrame) -> None:
        self.metrics = metrics

    def _rows(self, setting: str, policies: tuple[str, ...], columns: list[str]) -> pd.DataFrame | None:
        if any(c not in self.metrics.columns for c in columns):
            return None
        rows = self.metrics[(self.metrics["setting"] == setting) & self.metrics["policy"].isin(policies)]
        if set(rows["policy"]) != set(policies) or rows[columns].isna().all(axis=None):
            return None  # a pooled row needs every policy it pools
        return rows[[*KEYS, *columns]].reset_index(drop=True)

    def get(self, ref: Ref) -> Estimate | None:
        """The estimate of ``ref``; None when the run lacks its rollouts or columns.

        Statistics: ``mean`` (a paired delta when ``ref.base_setting`` is set) and ``pooled``
        (revisions per audit, pooled over episodes).
        """
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

    def _paired(self, ref: Ref) -> Estimate | None:
        assert ref.base_setting is not None
        if ref.metric not in self.metrics.columns:
            return None
        both = self.metrics[self.metrics["policy"].isin(ref.policies)]
        frame = paired_deltas(both, ref.base_setting, ref.setting, [ref.metric]).frame
        if set(frame["policy"]) != set(ref.policies):
            return None
        return Estimate(frame[[*KEYS, ref.metric]], _weighted_mean(frame[ref.metric].to_numpy(dtype=float)))


__all__ = ["KEYS", "Estimate", "RunEstimates", "difference"]
