"""The task seam: what a market supplies (:class:`Task`) and the registry that names them.

See :mod:`solarchain_eval.tasks.base` for the interface and docs/architecture.md ("Tasks"), and
:mod:`solarchain_eval.tasks.governance_view` for what a task supplies to the Planner/Auditor layer.
"""

from .base import DIMENSIONS, DIRECTIONS, Lever, MetricSpec, Task, metric_names, metrics_of
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
    "EpisodeRisk",
    "GovernancePrompts",
    "GovernanceView",
    "GovernedTask",
    "Lever",
    "LeverCodec",
    "MetricSpec",
    "NoGovernanceViewError",
    "Task",
    "UnknownTaskError",
    "diagnostic_names_of",
    "diagnostic_outcomes_of",
    "get_task",
    "governance_view_of",
    "harm_outcome_of",
    "metric_names",
    "metrics_of",
    "register_task",
    "task_names",
    "unregister_task",
]
