"""The task seam: what a market supplies (:class:`Task`) and the registry that names them.

See :mod:`solarchain_eval.tasks.base` for the interface and docs/architecture.md ("Tasks").
"""

from .base import DIMENSIONS, DIRECTIONS, Lever, MetricSpec, Task, metric_names, metrics_of
from .registry import DEFAULT_TASK, UnknownTaskError, get_task, register_task, task_names, unregister_task

__all__ = [
    "DEFAULT_TASK",
    "DIMENSIONS",
    "DIRECTIONS",
    "Lever",
    "MetricSpec",
    "Task",
    "UnknownTaskError",
    "get_task",
    "metric_names",
    "metrics_of",
    "register_task",
    "task_names",
    "unregister_task",
]
