"""Training throughput (SB3 steps/s per algorithm) and the paper preset's wall time.

Steps/s are measured in steady state with one torch thread: a short warm-up learn (past
DQN's and SAC's learning starts, and one PPO rollout), then a timed ``learn`` continuing the
same model. The same measurement on a trivial env with the same spaces (constant observation,
zero reward, 24-step episodes) gives SB3's own ceiling, so the env's share of a training step
is ``1 - env_rate / trivial_rate``.

The paper-preset wall time is estimated by simulating the grid's scheduler (the plan's order,
dependencies, ``K`` workers each taking the first ready unit) on per-unit durations: a train
unit lasts ``overhead + 300,000 / steps_per_s`` and an eval unit its measured time. The
durations come either from these micro-benchmarks or, better, from the per-unit times of a
real (reduced-budget) grid run (:func:`unit_times_from_root`), which include the contention of
workers sharing the cores.
"""

from __future__ import annotations

import json
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ..agents.checkpoints import ACTION_MODES, algorithm_class
from ..config import BenchmarkConfig
from ..experiments.grid import GridSpec, Unit, plan_units
from ..experiments.layout import PAPER_METADATA_FILE, UNITS_DIR
from ..protocol import PAPER_SEED
from ..tasks.registry import DEFAULT_TASK, get_task
from ..training.sb3_session import quiet_logger, set_torch_threads
from ..training.sb3_spec import TRAIN_METADATA_FILE, hyperparameters
from .env_bench import Throughput, task_data

#: Timed steps per repeat and warm-up steps (past learning starts / one PPO rollout).
DEFAULT_STEPS = {"ppo": 6144, "sac": 1000, "dqn": 6000}
WARMUP_STEPS = {"ppo": 2048, "sac": 200, "dqn": 400}


class TrivialEnv(gym.Env):
    """A task's spaces (default: the solar market's) with nothing behind them: SB3's own cost per step."""

    def __init__(self, action_mode: str = "continuous", task: str = DEFAULT_TASK) -> None:
        like = task_env(action_mode, None, task)
        self.observation_space = like.observation_space
        self.action_space = like.action_space
        self._obs = np.zeros(self.observation_space.shape, dtype=np.float32)
        self._k = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._k = 0
        return self._obs.copy(), {}

    def step(self, action: Any):
        self._k += 1
        return self._obs.copy(), 0.0, False, self._k >= 24, {}


def training_steps_per_s(
    algo: str, env: gym.Env, steps: int, repeats: int, seed: int = 0, cpu_rates: list[float] | None = None
) -> Throughput:
    """Median-ready samples of steady-state SB3 training speed (one torch thread).

    ``cpu_rates``, if given, receives each repeat's steps per CPU second of this process (a
    figure that the machine's other load distorts less than the wall-clock one).
    """
    from ..config import BenchmarkConfig

    set_torch_threads(1)
    params = hyperparameters(algo, BenchmarkConfig(), 300_000)
    samples = []
    for repeat in range(repeats):
        model = algorithm_class(algo)("MlpPolicy", env, seed=seed + repeat, verbose=0, device="cpu", **params)
        model.set_logger(quiet_logger())
        model.learn(WARMUP_STEPS[algo])
        before = model.num_timesteps
        start, cpu = time.perf_counter(), time.process_time()
        model.learn(steps, reset_num_timesteps=False)
        samples.append((model.num_timesteps - before) / (time.perf_counter() - start))
        if cpu_rates is not None:
            cpu_rates.append((model.num_timesteps - before) / max(time.process_time() - cpu, 1e-9))
    return Throughput(f"{algo.upper()} training", "steps/s", tuple(samples))


def task_env(action_mode: str, data_dir: Path | None, task: str = DEFAULT_TASK) -> gym.Env:
    """A fresh env of the task on its dataset in ``data_dir`` (None: its default), default config."""
    market = get_task(task)
    return market.make_env(BenchmarkConfig(), task_data(market, data_dir), action_mode=action_mode)


def solarchain_env(algo: str, data_dir: Path | None, task: str = DEFAULT_TASK) -> gym.Env:
    """The env ``algo`` trains on (its action mode) in the task (default: the solar market)."""
    return task_env(ACTION_MODES[algo], data_dir, task)


@dataclass(frozen=True)
class UnitTimes:
    """Inputs of the wall-time estimate: training speed per algorithm, fixed costs, eval times."""

    steps_per_s: dict[str, float]
    train_overhead_s: float
    eval_s: dict[str, float]  # per policy, one eval unit of ``episodes`` episodes
    source: str
    episodes: int = 30
    train_overhead_by_algo: dict[str, float] = field(default_factory=dict)  # where it differs (JAX: compilation)


def unit_times_from_root(root: Path) -> UnitTimes:
    """Per-unit times of a finished grid run (its DONE markers and training metadata)."""
    root = Path(root)
    rates: dict[str, list[float]] = {}
    overheads: list[float] = []
    evals: dict[str, list[float]] = {}
    for done in sorted((root / UNITS_DIR).glob("*/*/DONE")):
        unit_dir = done.parent
        wall = float(json.loads(done.read_text())["wall_s"])
        policy = unit_dir.name.split("-")[0]
        if unit_dir.parent.name == "train":
            # A JAX seed group keeps one metadata file per seed (seed_<s>/), all with the group's times.
            path = unit_dir / TRAIN_METADATA_FILE
            meta = json.loads(
                (path if path.is_file() else min(unit_dir.glob(f"seed_*/{TRAIN_METADATA_FILE}"))).read_text()
            )
            rates.setdefault(policy, []).append(meta["timesteps_done"] / meta["wall_s"])
            overheads.append(max(wall - meta["wall_s"], 0.0))
        else:
            evals.setdefault(policy, []).append(wall)
    if not rates:
        raise ValueError(f"{root} has no finished train units to take times from")
    episodes = int(json.loads((root / PAPER_METADATA_FILE).read_text())["grid"]["episodes"])
    return UnitTimes(
        {a: statistics.median(v) for a, v in rates.items()},
        statistics.median(overheads),
        {p: statistics.median(v) for p, v in evals.items()},
        f"per-unit times of {root}",
        episodes,
    )


def unit_duration(unit: Unit, times: UnitTimes, spec: GridSpec) -> float:
    """Seconds of one unit: training scales with the timesteps, evaluation with the episodes.

    ``times.steps_per_s`` is per model of a train unit as planned (a JAX seed group's models
    train at once, so the group takes the time of one model at the group's rate).
    """
    if unit.kind == "train":
        overhead = times.train_overhead_by_algo.get(unit.policy, times.train_overhead_s)
        return overhead + spec.timesteps / times.steps_per_s[unit.policy]
    measured = times.eval_s.get(unit.policy, max(times.eval_s.values(), default=1.0))
    return measured * spec.episodes / times.episodes


def simulate_wall_time(units: Sequence[Unit], durations: dict[str, float], workers: int) -> float:
    """Makespan of list scheduling as :func:`~.experiments.pool.run_units` does it."""
    pending = list(units)
    done: set[str] = set()
    running: list[tuple[float, str]] = []
    now = 0.0
    while pending or running:
        for unit in list(pending):
            if len(running) >= workers:
                break
            if all(dep in done for dep in unit.depends_on):
                pending.remove(unit)
                running.append((now + durations[unit.name], unit.name))
        running.sort()
        now, name = running.pop(0)
        done.add(name)
    return now


def estimate_paper_wall_time(times: UnitTimes, workers: int, spec: GridSpec | None = None) -> dict[str, float]:
    """Estimated wall time (s) of the paper preset (or ``spec``) on ``workers`` workers."""
    spec = spec or GridSpec.from_preset("paper")
    units = plan_units(spec)
    durations = {u.name: unit_duration(u, times, spec) for u in units}
    per_algo = {
        algo: sum(d for u_name, d in durations.items() if u_name.startswith(f"train/{algo}-"))
        for algo in times.steps_per_s
    }
    return {
        "wall_s": simulate_wall_time(units, durations, workers),
        "cpu_s": sum(durations.values()),
        **{f"train_{algo}_cpu_s": s for algo, s in per_algo.items()},
    }


def measured_unit_times(data_dir: Path, steps_per_s: dict[str, float], episodes: int = 30) -> UnitTimes:
    """Unit times from micro-benchmarks: eval units timed once (a baseline and each learned
    policy with an untrained model), train overhead = a 1-step training's wall time."""
    import tempfile

    from ..evaluation.run_spec import EvaluationSpec
    from ..evaluation.runner import run_evaluation
    from ..training.sb3_spec import TrainSpec
    from ..training.sb3_trainer import train

    evals: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        train(TrainSpec(algo="dqn", seed=0, timesteps=1, data_dir=data_dir, checkpoint_every=0), Path(tmp) / "t")
        overhead = time.perf_counter() - start
        for policy in ("static", "random", "myopic", *steps_per_s):
            models = {}
            if policy in ACTION_MODES:
                model = algorithm_class(policy)("MlpPolicy", solarchain_env(policy, data_dir), seed=0, device="cpu")
                models[policy] = Path(tmp) / f"{policy}.zip"
                model.save(models[policy])
            spec = EvaluationSpec(
                policies=[policy], run_seeds=[PAPER_SEED], episodes=episodes, data_dir=data_dir, models=models
            )
            start = time.perf_counter()
            run_evaluation(spec, Path(tmp) / policy, command=["bench-train"])
            evals[policy] = time.perf_counter() - start
    return UnitTimes(dict(steps_per_s), overhead, evals, "micro-benchmarks (one process, no contention)", episodes)
