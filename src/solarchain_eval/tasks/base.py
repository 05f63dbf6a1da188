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
from numbers import Integral
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

    # -- evaluation and records (the runner, run_metadata.json, the fingerprint, verify) --
    # A task without a dataset returns None from data_dir and load_data, and provenance
    # {"data_dir": None, "files": {}}: its episodes depend on the config and the episode seed alone.

    def default_config(self) -> Any:
        """The configuration of an evaluation that gives none (the solar market: ``BenchmarkConfig()``)."""
        ...

    def setting_config(self, config: Any, *, no_physics_penalty: bool) -> Any:
        """``config`` with a setting's reward switch applied (a task without one returns ``config``)."""
        ...

    def config_record(self, config: Any) -> dict[str, Any]:
        """``config`` as the JSON object ``run_metadata.json`` records under ``config``."""
        ...

    def config_from_record(self, record: Mapping[str, Any]) -> Any:
        """The configuration :meth:`config_record` recorded, validated.

        Raises
        ------
        ValueError
            The record is not one this task reads (pydantic's ``ValidationError`` is one).
        """
        ...

    def protocol_config(self, config: Any) -> dict[str, Any]:
        """The parts of ``config`` that decide the task (hashed into the protocol's ``config_sha256``);
        paths, training budgets and evaluation defaults stay out."""
        ...

    def episode_steps(self, config: Any) -> int:
        """Steps per episode under ``config`` (to estimate a run's record size before any work)."""
        ...

    def step_extra_names(self, data: Any) -> tuple[str, ...]:
        """What each of :meth:`step_extras`' values is (the solar market: the dataset's cities); empty
        when the task records none, and then the run has no ``city_hour_policy`` table."""
        ...


def observation_names_of(task: Task) -> tuple[str, ...] | None:
    """The names of the task's observation features, in order, when the task declares them.

    ``observation_names`` is an optional attribute of a task (the solar market's twelve features);
    agents behind HTTP receive the names with each observation, and a trained model's observation
    shape is checked against their number. None: the task declares none (nothing is checked).
    """
    names = getattr(task, "observation_names", None)
    return None if names is None else tuple(str(n) for n in names)


def metric_names(task: Task) -> tuple[str, ...]:
    """The task's episode-metric column names, in order."""
    return tuple(m.name for m in task.metrics)


def headline_metrics_of(task: Task) -> tuple[MetricSpec, ...]:
    """The metrics a results table printed in a terminal shows (all of them stay in ``metrics.csv``).

    The task's optional ``headline_metrics`` attribute (metric names, in order), else the first
    ranked metric (direction ``higher`` or ``lower``) of each template dimension.

    Raises
    ------
    ValueError
        ``headline_metrics`` names a metric the task does not declare.
    """
    declared = {m.name: m for m in task.metrics}
    names = getattr(task, "headline_metrics", None)
    if names is not None:
        unknown = [n for n in names if n not in declared]
        if unknown:
            raise ValueError(f"task {task.name!r}: headline_metrics names undeclared metric(s) {', '.join(unknown)}")
        return tuple(declared[n] for n in names)
    firsts = (next((m for m in metrics_of(task, d) if m.direction != "none"), None) for d in DIMENSIONS)
    return tuple(m for m in firsts if m is not None)


def metrics_of(task: Task, dimension: str) -> tuple[MetricSpec, ...]:
    """The task's metrics of one template dimension (:data:`DIMENSIONS`)."""
    if dimension not in DIMENSIONS:
        raise ValueError(f"unknown dimension {dimension!r} (one of {', '.join(DIMENSIONS)})")
    return tuple(m for m in task.metrics if m.dimension == dimension)


#: Steps in one day of a task without a ``steps_per_day`` attribute: the solar market's (one step = one hour).
DEFAULT_STEPS_PER_DAY = 24


def steps_per_day_of(task: Task | None) -> int:
    """How many of the task's steps make one day (its optional ``steps_per_day`` attribute).

    The report clusters episodes by start day, ``start_hour // steps_per_day`` (``start_hour`` is
    the episode's first step, counted from the dataset's first): 24 for the solar market and any
    task without the attribute (one step = one hour), 1 for the supply-chain market (one step = one
    day). ``None`` (a run that records no task) is the solar market.

    Raises
    ------
    ValueError
        The attribute is not a positive integer.
    """
    value = getattr(task, "steps_per_day", None) if task is not None else None
    if value is None:
        return DEFAULT_STEPS_PER_DAY
    if isinstance(value, bool) or not isinstance(value, Integral) or int(value) < 1:
        name = getattr(task, "name", type(task).__name__)
        raise ValueError(f"task {name!r}: steps_per_day must be a positive integer, got {value!r}")
    return int(value)


# --- the report's and the leaderboard's concern: a task's paper reference (optional attributes) ---
# These attributes are optional: a task without them has none (read them with the helpers below),
# so they are not members of the Task protocol that ``register_task`` checks.


@dataclass(frozen=True)
class PaperReference:
    """What a task's paper published, as the report and the leaderboard use it.

    A task that has one (the solar market) gets the paper's own tables in its report and the
    paper's rows on boards of the paper's protocol; a task without one gets the generic tables
    (one per template dimension) and a board laid out from its metric declarations alone.

    Attributes
    ----------
    dataset_sha256 : mapping of str to str
        The published dataset's files and their sha256 (part of the paper's protocol).
    metrics : tuple of str
        The metrics the paper's tables and board cover. A declared metric not among them is
        shown in its dimension's generic table and on the board after the paper's columns.
    board_metrics : tuple of str
        The metrics the paper's board shows beside the ranked one, in order.
    headers : mapping of str to str
        A metric's short name on the board (``cumulative_reward`` -> ``reward``), where the paper's
        board has one; other metrics are shown by their column name, unit and direction.
    """

    dataset_sha256: Mapping[str, str]
    metrics: tuple[str, ...]
    board_metrics: tuple[str, ...]
    headers: Mapping[str, str]


def paper_reference_of(task: Task) -> PaperReference | None:
    """The task's :class:`PaperReference` (its optional ``paper_reference`` attribute), or None."""
    return getattr(task, "paper_reference", None)


def dataset_manifest_of(task: Task) -> str | None:
    """The file in a dataset directory of the task that records how it was built (its optional
    ``dataset_manifest`` attribute, the solar market's ``manifest.json``), or None."""
    return getattr(task, "dataset_manifest", None)


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


# --- the sweep's concern: the episode cost a constrained learner bounds (an optional attribute) ---


def episode_cost_fields(task: Task) -> tuple[str, ...]:
    """The step fields whose sum over an episode's steps is its ``episode_cost``, Σ_t (V_t + A_t),
    the quantity PPO-Lagrangian constrains (the sweep's results carry it).

    The task's optional ``episode_cost_fields`` attribute (the solar market: its violation rate and
    unsafe-backed energy, added step by step); without it, ``("cost",)`` when the task records a
    ``cost`` step field, else none (the results then have no ``episode_cost``).
    """
    declared = getattr(task, "episode_cost_fields", None)
    if declared is not None:
        return tuple(declared)
    return ("cost",) if "cost" in task.step_fields else ()
