"""Throughput measurements of a task's environments and the evaluation runner.

Timings on shared machines vary from run to run, so every figure is measured several times
and reported as median and best. The environments are the task's
(:func:`~solarchain_eval.tasks.registry.get_task`; default the solar market) on its dataset in
``data_dir`` (None: the task's default) with the default configuration.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BenchmarkConfig
from ..protocol import PAPER_SEED
from ..tasks.base import Task, make_jax_env, make_vector_env
from ..tasks.registry import DEFAULT_TASK, get_task


@dataclass(frozen=True)
class Throughput:
    name: str
    unit: str
    samples: tuple[float, ...]

    @property
    def median(self) -> float:
        return statistics.median(self.samples)

    @property
    def best(self) -> float:
        return max(self.samples)


def task_data(task: Task, data_dir: Path | None) -> Any:
    """The task's dataset in ``data_dir`` (None: its default), as its env factories take it."""
    return task.load_data(task.data_dir(data_dir, BenchmarkConfig()))


def task_jax_env(task: str, data_dir: Path | None) -> Any:
    """The task's JAX env on its dataset with the default configuration.

    Raises
    ------
    ValueError
        The task has no JAX env.
    """
    market = get_task(task)
    env = make_jax_env(market, BenchmarkConfig(), task_data(market, data_dir))
    if env is None:
        raise ValueError(f"task {task!r} has no JAX environment")
    return env


def uniform_actions(space: Any, rows: tuple[int, ...], seed: int) -> np.ndarray:
    """``rows`` of actions drawn uniformly from the Box ``space`` up front (float32)."""
    u = np.random.default_rng(seed).random((*rows, *space.shape), dtype=np.float32)
    low, high = np.float32(space.low), np.float32(space.high)
    # the [0, 1] box of the solar market keeps its draws exactly
    return u if np.all(low == 0) and np.all(high == 1) else low + (high - low) * u


def with_make_wrappers(env: Any) -> Any:
    """``env`` inside the wrappers ``gymnasium.make`` adds (the env checker, order enforcing)."""
    from gymnasium.wrappers import OrderEnforcing, PassiveEnvChecker

    return OrderEnforcing(PassiveEnvChecker(env))


def single_env_steps_per_s(data_dir: Path | None, steps: int, repeats: int, task: str = DEFAULT_TASK) -> Throughput:
    """One env of the task with ``gymnasium.make``'s wrappers, random actions, resets included.

    Actions are drawn up front from a uniform generator so the figure measures the env, not
    ``Box.sample``.
    """
    return single_envs_steps_per_s(data_dir, steps, repeats, (task,))[0]


def single_envs_steps_per_s(
    data_dir: Path | None, steps: int, repeats: int, tasks: tuple[str, ...]
) -> list[Throughput]:
    """:func:`single_env_steps_per_s` of several tasks in one run, their repeats interleaved.

    Repeat r of every task runs before repeat r + 1 of any, so that a shared machine's load
    weighs on them alike and the ratio of their medians compares like with like. ``data_dir``
    is the first task's (the others run on their default datasets).
    """
    envs, actions = [], []
    for index, task in enumerate(tasks):
        market = get_task(task)
        env = with_make_wrappers(
            market.make_env(BenchmarkConfig(), task_data(market, data_dir if index == 0 else None))
        )
        envs.append(env)
        actions.append(uniform_actions(env.action_space, (steps,), 0))
    samples: list[list[float]] = [[] for _ in tasks]
    for repeat in range(repeats):
        for env, drawn, out in zip(envs, actions, samples, strict=True):
            env.reset(seed=repeat)
            start = time.perf_counter()
            for action in drawn:
                _, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    env.reset()
            out.append(steps / (time.perf_counter() - start))
    for env in envs:
        env.close()
    return [
        Throughput(
            "single env (gym.make, random actions, resets included)" + (f", task {task}" if len(tasks) > 1 else ""),
            "steps/s",
            tuple(out),
        )
        for task, out in zip(tasks, samples, strict=True)
    ]


def vector_env_steps_per_s(
    data_dir: Path | None, num_envs: int, calls: int, repeats: int, task: str = DEFAULT_TASK
) -> Throughput:
    """The task's vector env (SAME_STEP autoreset): every call is ``num_envs`` transitions.

    A vector env without SAME_STEP (its factory raises ValueError) runs with its default
    (NEXT_STEP: a call that resets a sub-env is one of its calls all the same), and says so.
    """
    market = get_task(task)
    data, mode = task_data(market, data_dir), ""
    try:
        envs = make_vector_env(market, BenchmarkConfig(), data, num_envs, autoreset_mode="SameStep")
    except ValueError:
        envs, mode = make_vector_env(market, BenchmarkConfig(), data, num_envs), "; NEXT_STEP autoreset"
    actions = uniform_actions(envs.single_action_space, (8, num_envs), 1)
    envs.reset(seed=0)
    for i in range(25):  # warm-up: one full episode with its autoreset
        envs.step(actions[i % 8])
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for i in range(calls):
            envs.step(actions[i % 8])
        samples.append(calls * num_envs / (time.perf_counter() - start))
    envs.close()
    return Throughput(f"vector env, {num_envs} envs (resets included{mode})", "env-steps/s", tuple(samples))


def evaluation_seconds(data_dir: Path, repeats: int) -> Throughput:
    """Wall time of 1,620 baseline episodes (3 policies × 2 settings × 9 seeds × 30 episodes), files written."""
    from ..evaluation.run_spec import EvaluationSpec
    from ..evaluation.runner import run_evaluation

    samples = []
    seeds = tuple(PAPER_SEED + i for i in range(9))
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            for no_physics in (False, True):
                spec = EvaluationSpec(
                    policies=["static", "random", "myopic"],
                    run_seeds=seeds,
                    episodes=30,
                    data_dir=data_dir,
                    no_physics_penalty=no_physics,
                )
                run_evaluation(spec, Path(tmp) / str(no_physics), command=["bench"])
            samples.append(time.perf_counter() - start)
    return Throughput("evaluate 1,620 baseline episodes (with output files)", "s", tuple(samples))


def warm_table(data_dir: Path | None, task: str = DEFAULT_TASK) -> Any:
    """Load the task's dataset once (a later load is then served warm)."""
    return task_data(get_task(task), data_dir)
