"""What a market supplies to the benchmark: the :class:`Task` interface.

The benchmark's template (utility, safety, stability, fairness, auditability; a feasibility
oracle; an auditable governance layer) is generic; a *task* is one market that fills it in. The
generic wings (evaluation, governance, training, experiments, report, CLI) reach a market only
through this interface, obtained by name from :mod:`.registry`; a task's own modules (its
dataset, dynamics and environments) are its internals. The solar market
(:mod:`solarchain_eval.solar`) is the first task.

A task is an object with the attributes and methods of :class:`Task`. It is modelled on
Gymnasium's registration (an id and a factory) and gymnax's ``Environment`` (parameters passed in,
nothing global): every method takes the config and data it needs and returns new objects.

This module imports nothing from the package beyond the bottom layer, so every wing may use it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from ..records_schema import Column

#: The template's dimensions: every episode metric a task declares belongs to one.
DIMENSIONS = ("utility", "safety", "stability", "fairness", "auditability")
#: Whether a larger value of a metric is better (``higher``) or worse (``lower``), or neither (``none``:
#: a state the report shows but does not rank by).
DIRECTIONS = ("higher", "lower", "none")


@dataclass(frozen=True)
class Lever:
    """One component of the action: its name (the ``actions.csv`` column), unit and executed range."""

    name: str
    unit: str
    low: float
    high: float
    meaning: str = ""


@dataclass(frozen=True)
class MetricSpec:
    """One episode metric of a task, declared once: its ``metrics.csv`` column and how to read it.

    Attributes
    ----------
    column : Column
        The column (name, unit, meaning) as :mod:`~solarchain_eval.records_schema` describes columns.
    dimension : str
        One of :data:`DIMENSIONS`.
    direction : str
        One of :data:`DIRECTIONS`.
    """

    column: Column
    dimension: str
    direction: str

    def __post_init__(self) -> None:
        if self.dimension not in DIMENSIONS:
            raise ValueError(f"metric {self.column.name!r}: dimension {self.dimension!r} is not one of {DIMENSIONS}")
        if self.direction not in DIRECTIONS:
            raise ValueError(f"metric {self.column.name!r}: direction {self.direction!r} is not one of {DIRECTIONS}")

    @property
    def name(self) -> str:
        return self.column.name

    @property
    def unit(self) -> str:
        return self.column.unit


@runtime_checkable
class Task(Protocol):
    """The interface a market implements (see the module docstring).

    Attributes
    ----------
    name : str
        The task's name (``--task NAME``), lowercase letters, digits and ``-``.
    env_id : str
        Its Gymnasium id (``gym.make(env_id)``); part of every run's protocol.
    levers : tuple of Lever
        The action's components, in order.
    step_fields : tuple of str
        The per-step record columns its env's ``info`` carries (``actions.csv``), in order.
    metrics : tuple of MetricSpec
        Its episode metrics, in ``metrics.csv`` column order.
    """

    name: str
    env_id: str
    levers: tuple[Lever, ...]
    step_fields: tuple[str, ...]
    metrics: tuple[MetricSpec, ...]

    def data_dir(self, data_dir: str | Path | None, config: Any) -> Path:
        """The dataset directory an evaluation uses: ``data_dir``, else the config's, else the task's default."""
        ...

    def load_data(self, data_dir: Path) -> Any:
        """The validated dataset (an hourly table) in ``data_dir``; a one-line error naming the file otherwise."""
        ...

    def provenance(self, data: Any) -> dict[str, Any]:
        """Where ``data`` came from: ``data_dir`` and the sha256 of each dataset file (``files``)."""
        ...

    def make_env(self, config: Any, data: Any, *, action_mode: str | None = None) -> Any:
        """A fresh Gymnasium environment of this task on ``data`` with ``config``; ``action_mode``
        ``"continuous"`` or ``"discrete"`` (None: the one the config implies)."""
        ...

    def episode_metrics(self, steps: Mapping[str, list], env: Any) -> dict[str, float]:
        """The episode metrics (the :attr:`metrics` columns, in order) of one finished episode.

        ``steps`` holds the :attr:`step_fields` of every step; ``env`` is the environment after
        the episode's last step (for state a step record does not carry).
        """
        ...

    def step_extras(self, info: Mapping[str, Any]) -> tuple[float, ...]:
        """Per-step values recorded beside the step fields (the solar market: each city's reward)."""
        ...

    def identity(self, config: Any) -> dict[str, Any]:
        """What the task contributes to a run's protocol fingerprint (its env id and market config)."""
        ...

    def baselines(self) -> Mapping[str, Callable[..., Any]]:
        """The task's reference policies by name, each a factory taking the config."""
        ...


def metric_names(task: Task) -> tuple[str, ...]:
    """The task's episode-metric column names, in order."""
    return tuple(m.name for m in task.metrics)


def metrics_of(task: Task, dimension: str) -> tuple[MetricSpec, ...]:
    """The task's metrics of one template dimension (:data:`DIMENSIONS`)."""
    if dimension not in DIMENSIONS:
        raise ValueError(f"unknown dimension {dimension!r} (one of {', '.join(DIMENSIONS)})")
    return tuple(m for m in task.metrics if m.dimension == dimension)


# --- training's concern: vector and JAX environments, the training log (optional capabilities) ---
# A task may have these attributes; one without them gets the defaults below (a vector env over
# make_env, no JAX env, a training log of the return and length only). They are optional, so they
# are not members of the Task protocol that ``register_task`` checks; read them with the helpers.


@dataclass(frozen=True)
class TrainLogField:
    """One per-episode column of ``training_log.csv``: an ``info`` value of each step, summed or averaged.

    Attributes
    ----------
    column : str
        The column's name.
    info_key : str
        The key of the env's per-step ``info`` it accumulates.
    mean : bool
        The episode mean of the values (else their sum).
    """

    column: str
    info_key: str
    mean: bool = False


def make_vector_env(
    task: Task,
    config: Any,
    data: Any,
    n_envs: int,
    *,
    action_mode: str | None = None,
    autoreset_mode: str | None = None,
) -> Any:
    """``n_envs`` environments of ``task`` stepped together, as a Gymnasium ``VectorEnv``.

    The task's own ``make_vector_env(config, data, n_envs, action_mode=..., autoreset_mode=...)``
    where it has one (the solar market: its native batched env); otherwise Gymnasium's
    ``SyncVectorEnv`` over :meth:`Task.make_env`. ``autoreset_mode`` is a Gymnasium
    ``AutoresetMode`` value (``"NextStep"``, the default, or ``"SameStep"``).
    """
    own = getattr(task, "make_vector_env", None)
    if own is not None:
        return own(config, data, n_envs, action_mode=action_mode, autoreset_mode=autoreset_mode)
    from gymnasium.vector import AutoresetMode, SyncVectorEnv

    return SyncVectorEnv(
        [lambda: task.make_env(config, data, action_mode=action_mode)] * n_envs,
        autoreset_mode=AutoresetMode(autoreset_mode or AutoresetMode.NEXT_STEP),
    )


def make_jax_env(task: Task, config: Any, data: Any, *, action_mode: str | None = None) -> Any | None:
    """The task's jittable environment (a gymnax ``Environment`` whose ``default_params`` hold
    ``config`` and ``data``; the JAX trainer's functional ``reset``/``step``, observation and action
    spaces), from its optional ``make_jax_env(config, data, action_mode=...)``; None when it has none."""
    own = getattr(task, "make_jax_env", None)
    return None if own is None else own(config, data, action_mode=action_mode)


def has_jax_env(task: Task) -> bool:
    """Whether ``task`` has a JAX environment (``train --backend jax`` and the JAX benches need one)."""
    return getattr(task, "make_jax_env", None) is not None


def training_log_fields(task: Task) -> tuple[TrainLogField, ...]:
    """The task's ``training_log.csv`` columns beyond the return and length (its optional
    ``training_log`` attribute; none without it)."""
    return tuple(getattr(task, "training_log", ()))
