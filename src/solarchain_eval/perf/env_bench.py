"""Throughput measurements of the environments and the evaluation runner.

Timings on shared machines vary from run to run, so every figure is measured several times
and reported as median and best.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

from ..data.table import HourlyTable, load_table
from ..envs.registration import ENV_ID
from ..protocol import PAPER_SEED


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


def single_env_steps_per_s(data_dir: Path, steps: int, repeats: int) -> Throughput:
    """One env through ``gymnasium.make`` (with its wrappers), random actions, resets included.

    Actions are drawn up front from a uniform generator so the figure measures the env, not
    ``Box.sample``.
    """
    env = gym.make(ENV_ID, data_dir=str(data_dir))
    actions = np.random.default_rng(0).random((steps, 3), dtype=np.float32)
    samples = []
    for repeat in range(repeats):
        env.reset(seed=repeat)
        start = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        samples.append(steps / (time.perf_counter() - start))
    env.close()
    return Throughput("single env (gym.make, random actions, resets included)", "steps/s", tuple(samples))


def vector_env_steps_per_s(data_dir: Path, num_envs: int, calls: int, repeats: int) -> Throughput:
    """The native vector env (SAME_STEP autoreset): every call is ``num_envs`` transitions."""
    envs = gym.make_vec(
        ENV_ID,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        data_dir=str(data_dir),
        autoreset_mode="SameStep",
    )
    actions = np.random.default_rng(1).random((8, num_envs, 3), dtype=np.float32)
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
    return Throughput(f"vector env, {num_envs} envs (resets included)", "env-steps/s", tuple(samples))


def evaluation_seconds(data_dir: Path, repeats: int) -> Throughput:
    """Wall time of 1,620 baseline episodes (3 policies × 2 settings × 9 seeds × 30 episodes), files written."""
    from ..evaluation.runner import EvaluationSpec, run_evaluation

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


def warm_table(data_dir: Path) -> HourlyTable:
    return load_table(data_dir)
