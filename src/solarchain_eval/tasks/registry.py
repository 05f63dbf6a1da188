"""Tasks by name: the one door through which generic code reaches a market.

Built-in tasks are named here with the module that defines them and imported on first use, so
that a generic wing depends on this registry, never on a task's modules (the architecture test
checks the imports; the module path below is data). Other packages add tasks through the
``solarchain_eval.tasks`` entry-point group (``NAME = "package.module:TASK"``), and code running
in-process (a test, a notebook) through :func:`register_task`.
"""

from __future__ import annotations

import importlib
import re
from importlib.metadata import entry_points
from typing import Any

from ..common.errors import OptionsError
from .base import Task

#: The task of every run that does not name one (the paper's solar market).
DEFAULT_TASK = "solar"
#: Built-in tasks: name -> "module:attribute" of the task object.
BUILTIN_TASKS = {
    "solar": "solarchain_eval.solar.task:SOLAR_TASK",
    "supply-chain": "solarchain_eval.supply.task:SUPPLY_TASK",
}
ENTRY_POINT_GROUP = "solarchain_eval.tasks"
#: The built-in tasks' Gymnasium registrations ("module:function"), run when the package is imported
#: so that ``gym.make("SolarChainEval-v0")`` works after ``import solarchain_eval``.
BUILTIN_ENV_REGISTRATIONS = (
    "solarchain_eval.envs.registration:register_envs",
    "solarchain_eval.supply.registration:register_supply_envs",
)
_NAME = re.compile(r"^[a-z][a-z0-9-]{0,39}$")

_registered: dict[str, Task] = {}


class UnknownTaskError(OptionsError, ValueError):
    """A task name that no built-in task, plugin or :func:`register_task` call provides."""


def register_task(task: Task) -> None:
    """Make ``task`` available by its name in this process (replacing a task of the same name)."""
    if not isinstance(task, Task):
        raise TypeError(f"{type(task).__name__} does not implement the Task interface (solarchain_eval.tasks.base)")
    if not _NAME.match(task.name):
        raise ValueError(f"task name {task.name!r}: use lowercase letters, digits and '-' (at most 40)")
    _registered[task.name] = task


def unregister_task(name: str) -> None:
    """Forget a task :func:`register_task` added (built-in tasks cannot be removed)."""
    _registered.pop(name, None)


def load_target(target: str) -> Any:
    """The object a ``"module:attribute"`` string names (the module imported now)."""
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


def register_builtin_envs() -> None:
    """Register the built-in tasks' environment ids with Gymnasium (idempotent)."""
    for target in BUILTIN_ENV_REGISTRATIONS:
        load_target(target)()


def _plugins() -> dict[str, str]:
    return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}


def task_names() -> tuple[str, ...]:
    """Every available task's name: built-in, registered in this process, and plugins."""
    return tuple(dict.fromkeys([*BUILTIN_TASKS, *_registered, *_plugins()]))


def get_task(name: str | None = None) -> Task:
    """The task called ``name`` (default: :data:`DEFAULT_TASK`).

    Raises
    ------
    UnknownTaskError
        No task has that name (the message lists the available ones).
    """
    name = name or DEFAULT_TASK
    if name in _registered:
        return _registered[name]
    target = BUILTIN_TASKS.get(name) or _plugins().get(name)
    if target is None:
        raise UnknownTaskError(f"unknown task {name!r} (available: {', '.join(task_names())})")
    task = load_target(target)
    if not isinstance(task, Task) or task.name != name:
        raise UnknownTaskError(f"task {name!r} ({target}) is not a Task named {name!r}")
    _registered[name] = task
    return task
