"""Training throughput of the JAX backend (rejax) beside SB3's, and its paper-preset wall time.

A training program is compiled once per algorithm (the compile time is reported on its own),
then run ``repeats`` times with fresh seeds' keys; each run trains ``steps`` env steps per seed
from scratch (so SAC's and DQN's first 100 steps, which do no update, are included: 5 % of
SAC's 2,000 steps). SAC's and DQN's replay buffer is sized for ``buffer_timesteps`` (the
paper's 300,000 in ``bench-train``), not for the short run: the buffer's size is part of the
cost of a step wherever sampling touches it. Wall time and the process's CPU time are both
recorded: XLA's CPU backend may use more than one thread, SB3 runs with one torch thread.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax

from ..agents.checkpoints import ACTION_MODES
from ..agents.jax_checkpoint import JAX_MODEL_FILE
from ..config import BenchmarkConfig
from ..protocol import PAPER_SEED
from ..tasks.base import make_jax_env
from ..tasks.registry import DEFAULT_TASK, get_task
from ..training.jax_algorithm import compile_training, rejax_config, seed_keys
from ..training.jax_trainer import save_network, write_train_config
from .env_bench import Throughput, task_data


def training_env(algo: str, data_dir: Path | None, config: BenchmarkConfig, task: str = DEFAULT_TASK) -> Any:
    """The task's JAX env that ``algo`` trains on (its action mode).

    Raises
    ------
    ValueError
        The task has no JAX env.
    """
    market = get_task(task)
    env = make_jax_env(market, config, task_data(market, data_dir), action_mode=ACTION_MODES[algo])
    if env is None:
        raise ValueError(f"task {task!r} has no JAX environment")
    return env


#: Env steps per seed per timed run.
DEFAULT_STEPS = {"ppo": 6144, "sac": 2000, "dqn": 6000}


@dataclass(frozen=True)
class JaxTrainingSpeed:
    """Steps/s of one algorithm: per model (``throughput``), the compile time and CPU use."""

    throughput: Throughput
    compile_s: float
    cached_compile_s: float  # the same program again, from the persistent compilation cache
    cpu_per_wall: float  # process CPU seconds per wall second while training (≈ threads busy), median
    seeds: int
    steps_per_cpu_s: float  # env steps of all seeds per CPU second of the process, median over repeats


def jax_training_steps_per_s(
    algo: str,
    data_dir: Path,
    steps: int,
    repeats: int,
    *,
    seeds: int = 1,
    config: BenchmarkConfig | None = None,
    model_dir: Path | None = None,
    buffer_timesteps: int | None = None,
    task: str = DEFAULT_TASK,
) -> JaxTrainingSpeed:
    """Steady rejax training speed of ``algo`` in env steps per second per model.

    Parameters
    ----------
    seeds : int
        Models trained at once in the vmap (the figure is per model; multiply for the total).
    model_dir : path, optional
        Write the last run's first model there (``jax_model.msgpack`` + ``train_config.json``),
        e.g. to time its evaluation.
    buffer_timesteps : int, optional
        Size SAC's and DQN's replay buffer for a training of this many steps (default: ``steps``).
    """
    cfg = config or BenchmarkConfig()
    env = training_env(algo, data_dir, cfg, task)
    batch = tuple(range(seeds))
    compiled, compile_s = compile_training(algo, batch, steps, env, cfg, buffer_timesteps=buffer_timesteps)
    _, cached_compile_s = compile_training(  # what a later train unit pays
        algo, batch, steps, env, cfg, buffer_timesteps=buffer_timesteps
    )
    samples, cpu_ratios, cpu_rates, states = [], [], [], None
    for repeat in range(repeats):
        keys = seed_keys(tuple(1000 * (repeat + 1) + s for s in batch))
        wall, cpu = time.perf_counter(), time.process_time()
        states, _ = jax.block_until_ready(compiled(keys))
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        done = int(states.global_step[0])
        samples.append(done / wall)
        cpu_ratios.append(cpu / wall)
        cpu_rates.append(done * seeds / max(cpu, 1e-9))
    if model_dir is not None and states is not None:
        save_network(Path(model_dir) / JAX_MODEL_FILE, algo, states, 0)
        write_train_config(
            Path(model_dir),
            {"identity": {"algo": algo, "backend": "jax"}, "rejax": rejax_config(algo, cfg, steps, buffer_timesteps)},
        )
    name = f"{algo.upper()} training (JAX on {jax.devices()[0].platform}, {seeds} seed(s) vmapped, per model)"
    return JaxTrainingSpeed(
        Throughput(name, "steps/s", tuple(samples)),
        compile_s,
        cached_compile_s,
        statistics.median(cpu_ratios),
        seeds,
        statistics.median(cpu_rates),
    )


def jax_eval_unit_s(algo: str, model_dir: Path, data_dir: Path, episodes: int = 30) -> float:
    """Seconds of one eval unit (one run seed × ``episodes``) of a JAX checkpoint, loading included."""
    from ..evaluation.run_spec import EvaluationSpec
    from ..evaluation.runner import run_evaluation

    spec = EvaluationSpec(
        policies=[algo], run_seeds=[PAPER_SEED], episodes=episodes, data_dir=data_dir, models={algo: model_dir}
    )
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run_evaluation(spec, Path(tmp) / "run", command=["bench-train"])
        return time.perf_counter() - start


def describe_flags() -> dict[str, Any]:
    """The XLA settings in force (they are read once, when JAX starts)."""
    import os

    return {"XLA_FLAGS": os.environ.get("XLA_FLAGS", ""), "devices": [str(d) for d in jax.devices()]}


@dataclass(frozen=True)
class ChunkingCost:
    """Steps/s per model of one training run three ways, alternately in one process."""

    algo: str
    seeds: int
    steps: int  # env steps per model and run
    chunk_steps: int
    one_loop: Throughput  # the trainer's loop program, the whole run in one call
    chunked: Throughput  # the same program per chunk, a checkpoint and a progress report after each
    rejax_train: Throughput  # rejax's own train (the initial state computed inside the program)
    checkpoint_mb: float
    checkpoint_s: float  # median seconds to write one checkpoint


def chunking_cost(
    algo: str,
    data_dir: Path,
    repeats: int,
    *,
    chunk_steps: int | None = None,
    chunks: int = 3,
    seeds: int = 3,
    buffer_timesteps: int | None = None,
    config: BenchmarkConfig | None = None,
    task: str = DEFAULT_TASK,
) -> ChunkingCost:
    """What training in chunks costs: ``chunks`` chunks of ``chunk_steps`` env steps per model
    (default: the trainer's) against the same steps in one call, ``repeats`` times each.

    The chunked run is the trainer's own (:func:`~..training.jax_chunks.run_chunks`): each
    chunk's state is fetched, written as a checkpoint into a temporary directory and reported.
    """
    from ..training.jax_chunks import ChunkedTraining, config_sha256, run_chunks
    from ..training.jax_progress import DEFAULT_CHUNK_STEPS

    cfg = config or BenchmarkConfig()
    env = training_env(algo, data_dir, cfg, task)
    batch = tuple(range(seeds))
    per_chunk = chunk_steps or DEFAULT_CHUNK_STEPS[algo]
    probe = ChunkedTraining(algo, batch, per_chunk, env, cfg, per_chunk, buffer_timesteps)
    steps = chunks * probe.plan.chunk_steps  # whole iterations (PPO rollouts, DQN's 4 envs)
    training = ChunkedTraining(algo, batch, steps, env, cfg, per_chunk, buffer_timesteps)
    training.compile()
    rejax, _ = compile_training(algo, batch, steps, env, cfg, buffer_timesteps=buffer_timesteps)
    one_loop, chunked, rejax_train, writes = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        checkpoint = Path(tmp) / "jax_chunks.npz"
        for _ in range(repeats):
            start = time.perf_counter()
            training.run()
            one_loop.append(steps / (time.perf_counter() - start))
            checkpoint.unlink(missing_ok=True)  # each chunked run starts from scratch
            start = time.perf_counter()
            run = run_chunks(training, checkpoint, config_sha256({"bench": algo}), on_progress=lambda p: None)
            chunked.append(steps / (time.perf_counter() - start))
            writes.append(run.checkpoint_s / max(run.chunks_run, 1))
            start = time.perf_counter()
            jax.block_until_ready(rejax(training.keys))
            rejax_train.append(steps / (time.perf_counter() - start))
        size_mb = checkpoint.stat().st_size / 1e6
    label = f"{algo.upper()} ({seeds} seed(s) vmapped, per model)"
    return ChunkingCost(
        algo,
        seeds,
        steps,
        training.plan.chunk_steps,
        Throughput(f"{label}, one call", "steps/s", tuple(one_loop)),
        Throughput(f"{label}, chunked", "steps/s", tuple(chunked)),
        Throughput(f"{label}, rejax train", "steps/s", tuple(rejax_train)),
        size_mb,
        statistics.median(writes),
    )
