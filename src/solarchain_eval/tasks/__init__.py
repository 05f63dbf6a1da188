"""The task seam: what a market supplies (:class:`Task`) and the registry that names them.

See :mod:`solarchain_eval.tasks.base` for the interface and docs/architecture.md ("Tasks"),
:mod:`solarchain_eval.tasks.governance_view` for what a task supplies to the Planner/Auditor layer,
and :mod:`solarchain_eval.tasks.dataset` for its optional dataset builder.
"""

from .base import DIMENSIONS, DIRECTIONS, Lever, MetricSpec, Task, metric_names, metrics_of
from .dataset import DatasetBuilder, NoDatasetBuilderError, ScenarioDatasetBuilder, dataset_of, has_dataset_builder
from .governance_view import (
    EpisodeRisk,
    GovernancePrompts,
    GovernanceView,
    GovernedTask,
    LeverCodec,
    NoGovernanceViewError,
    diagnostic_names_of,
    diagnostic_outcomes_of,
    governance_view_of,
    harm_outcome_of,
)
from .registry import DEFAULT_TASK, UnknownTaskError, get_task, register_task, task_names, unregister_task

__all__ = [
    "DEFAULT_TASK",
    "DIMENSIONS",
    "DIRECTIONS",
    "DatasetBuilder",
    "EpisodeRisk",
    "GovernancePrompts",
    "GovernanceView",
    "GovernedTask",
    "Lever",
    "LeverCodec",
    "MetricSpec",
    "NoDatasetBuilderError",
    "NoGovernanceViewError",
    "ScenarioDatasetBuilder",
    "Task",
    "UnknownTaskError",
    "dataset_of",
    "diagnostic_names_of",
    "diagnostic_outcomes_of",
    "get_task",
    "governance_view_of",
    "harm_outcome_of",
    "has_dataset_builder",
    "metric_names",
    "metrics_of",
    "register_task",
    "task_names",
    "unregister_task",
]
