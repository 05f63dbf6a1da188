"""``solarchain-eval train``: one PPO, SAC or DQN model (Stable-Baselines3, resumable), or one per
seed with the JAX backend (rejax, all seeds in one compiled ``vmap``)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import typer

from ..agents.checkpoints import TRAINABLE_ALGOS
from ..config import BenchmarkConfig, load_config
from ..protocol import PAPER_SEED
from ..tasks.base import has_jax_env
from ..tasks.registry import DEFAULT_TASK, get_task
from ..training.jax_progress import DEFAULT_CHUNK_STEPS
from ..training.lagrangian import DEFAULT_MULTIPLIER_LR, LAGRANGIAN_ALGO, LAGRANGIAN_LOG_FILE, LagrangianSettings
from ..training.sb3_spec import DEFAULT_CHECKPOINT_EVERY, TRAIN_LOG_FILE, TrainSpec
from ..training.sb3_trainer import TrainingError, check_algo, train
from . import app
from .common import (
    CliError,
    console,
    err_console,
    invoked_command,
    parse_seeds,
    progress_bar,
    register_user_error,
    reports_errors,
)
from .progress import TrainingProgress

register_user_error(TrainingError)


@app.command("train")
@reports_errors
def train_command(
    algo: str = typer.Option(
        ...,
        "--algo",
        help=f"Algorithm: {', '.join(TRAINABLE_ALGOS)} (DQN acts on the 125-point grid; ppo-lag is PPO-Lagrangian, "
        "which needs --cost-limit).",
    ),
    seed: int | None = typer.Option(None, "--seed", help=f"Training seed (default: the config seed, {PAPER_SEED})."),
    backend: str = typer.Option(
        "sb3",
        "--backend",
        help="sb3 (Stable-Baselines3, the reference) or jax (rejax on the JAX env; needs the jax extra; docs/jax.md).",
    ),
    seeds: str | None = typer.Option(
        None,
        "--seeds",
        help="JAX backend: comma-separated seeds trained at once in one vmap; "
        "one seed writes into --out, several into --out/seed_<s>/ (default: --seed).",
    ),
    timesteps: int | None = typer.Option(
        None,
        "--timesteps",
        min=1,
        help="Environment steps (default: the config's training.timesteps; the paper: 300000).",
    ),
    no_physics_penalty: bool = typer.Option(
        False, "--no-physics-penalty", help="Train on the ablation reward without λp (V + A)."
    ),
    data: Path | None = typer.Option(
        None, "--data", help="Dataset directory (default: the config's data_dir, else the embedded default dataset)."
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Training directory (default: <output_dir>/<time>_train_<algo>)."
    ),
    tensorboard: Path | None = typer.Option(
        None,
        "--tensorboard",
        help="TensorBoard log directory (SB3 scalars + per-episode violation and artificial liquidity).",
    ),
    checkpoint_every: int = typer.Option(
        DEFAULT_CHECKPOINT_EVERY,
        "--checkpoint-every",
        min=0,
        help="Timesteps between checkpoints (0: none; SB3 only: a JAX training checkpoints after every chunk).",
    ),
    chunk_steps: int | None = typer.Option(
        None,
        "--chunk-steps",
        min=1,
        help="JAX backend: env steps per compiled chunk, after which progress is shown and the state "
        f"checkpointed (default: {', '.join(f'{a.upper()} {n:,}' for a, n in DEFAULT_CHUNK_STEPS.items())}; "
        "the models do not depend on it).",
    ),
    torch_threads: int = typer.Option(
        1, "--torch-threads", min=1, help="torch threads (1 is fastest for these MLPs; SB3 only)."
    ),
    config: Path | None = typer.Option(None, "--config", help="YAML config in the paper's layout."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace a finished or different training in --out."),
    cost_limit: float | None = typer.Option(
        None,
        "--cost-limit",
        min=0.0,
        help="ppo-lag only: D, the limit on the expected episode cost (sum of info['cost'] = V + A over an episode).",
    ),
    multiplier_lr: float = typer.Option(
        DEFAULT_MULTIPLIER_LR,
        "--multiplier-lr",
        min=0.0,
        help="ppo-lag only: dual-ascent step size; after each rollout λ <- max(0, λ + lr (J_c - D)).",
    ),
    task: str = typer.Option(
        DEFAULT_TASK,
        "--task",
        help="The task to train on (default: the solar market; --backend jax needs its JAX env).",
    ),
) -> None:
    """Train one model with Stable-Baselines3 (MlpPolicy; learning rate, batch size and gamma from
    the config: 3e-4, 64, 0.98; SB3 defaults otherwise) and write model.zip, train_config.json,
    training_log.csv and train_metadata.json to --out.

    A killed run resumes from its last checkpoint when the same command is run again.
    --algo ppo-lag trains PPO-Lagrangian: PPO on r - λ c with λ updated by dual ascent after
    every rollout (docs/training.md#ppo-lagrangian); it also writes lagrangian_log.csv.
    Evaluate the model with: solarchain-eval evaluate --policies ALGO --models OUT

    --backend jax trains one model per --seeds seed with rejax (the same hyperparameters; the
    remaining differences are listed in docs/jax.md) and writes jax_model.msgpack,
    train_config.json and train_metadata.json per seed; evaluate --models loads them the same way.
    """
    cfg = load_config(config) if config else BenchmarkConfig()
    key = check_algo(algo)
    if key != LAGRANGIAN_ALGO and cost_limit is not None:
        raise TrainingError(f"--cost-limit applies to --algo {LAGRANGIAN_ALGO} only")
    # An invalid value is a TrainingError naming its option.
    lagrangian = LagrangianSettings(cost_limit, multiplier_lr) if cost_limit is not None else None
    steps = timesteps or cfg.training.timesteps
    out_dir = out or Path(cfg.output_dir) / f"{datetime.now().strftime('%Y%m%d-%H%M%S')}_train_{key}"
    if backend not in ("sb3", "jax"):
        raise CliError(f"unknown backend '{backend}' (choose from sb3, jax)")
    if backend == "jax" or seeds is not None:
        if backend != "jax":
            raise CliError("--seeds trains several seeds at once with --backend jax; SB3 takes one --seed")
        if tensorboard is not None:
            raise CliError("--tensorboard is for the SB3 backend (rejax writes no TensorBoard scalars)")
        if key == LAGRANGIAN_ALGO:
            raise CliError(f"--algo {LAGRANGIAN_ALGO} trains with Stable-Baselines3 only (not --backend jax)")
        if not has_jax_env(get_task(task)):
            raise CliError(f"--backend jax: task {task!r} has no JAX environment (train it with --backend sb3)")
        run_seeds = parse_seeds(seeds) if seeds else [cfg.seed if seed is None else seed]
        return _train_jax(key, run_seeds, steps, no_physics_penalty, data, cfg, out_dir, overwrite, chunk_steps, task)
    if chunk_steps is not None:
        raise CliError("--chunk-steps applies to --backend jax (SB3 checkpoints every --checkpoint-every steps)")
    spec = TrainSpec(
        algo=key,
        seed=cfg.seed if seed is None else seed,
        timesteps=steps,
        no_physics_penalty=no_physics_penalty,
        data_dir=data,
        config=cfg,
        checkpoint_every=checkpoint_every,
        tensorboard_dir=tensorboard,
        torch_threads=torch_threads,
        lagrangian=lagrangian,
        task=task,
    )
    err_console.print(f"training {key.upper()} for {steps:,} steps (seed {spec.seed}) into {out_dir}", soft_wrap=True)
    with progress_bar(f"training {key}", steps) as advance:
        done = [0]

        def report(now: int) -> None:
            advance(now - done[0])
            done[0] = now

        outcome = train(spec, out_dir, on_progress=report, overwrite=overwrite, command=invoked_command())
    if outcome.already_complete:
        console.print(
            f"{out_dir} already holds this finished training (pass --overwrite to train again)", soft_wrap=True
        )
    elif outcome.resumed_from:
        console.print(f"resumed from the checkpoint(s) at step {', '.join(map(str, outcome.resumed_from))}")
    console.print(
        f"{key.upper()}: {outcome.timesteps_done:,} steps in {outcome.wall_s:.1f} s "
        f"({outcome.steps_per_s:,.0f} steps/s in this session); model: {outcome.model_path}"
    )
    console.print(f"training log: {out_dir / TRAIN_LOG_FILE}", soft_wrap=True)
    if key == LAGRANGIAN_ALGO:
        console.print(f"multiplier log: {out_dir / LAGRANGIAN_LOG_FILE}", soft_wrap=True)


def _train_jax(
    algo: str,
    seeds: list[int],
    steps: int,
    no_physics_penalty: bool,
    data: Path | None,
    cfg: BenchmarkConfig,
    out_dir: Path,
    overwrite: bool,
    chunk_steps: int | None,
    task: str = DEFAULT_TASK,
) -> None:
    """``train --backend jax``: every seed in one compiled vmap, run in chunks (see docs/jax.md)."""
    try:
        from ..training.jax_trainer import JaxTrainSpec, seed_dirs, train_jax
    except ImportError as error:
        raise CliError(str(error)) from None
    spec = JaxTrainSpec(algo, tuple(seeds), steps, no_physics_penalty, data, cfg, chunk_steps, task=task)
    dirs = seed_dirs(out_dir, spec.seeds)
    err_console.print(
        f"training {algo.upper()} with JAX for {spec.timesteps:,} steps × {len(spec.seeds)} seed(s) into {out_dir} "
        "(compiling first: seconds on an idle CPU, up to minutes on a busy one)",
        soft_wrap=True,
    )
    label = f"{algo} (jax, seed{'s' if len(spec.seeds) > 1 else ''} {'+'.join(map(str, spec.seeds))})"
    with TrainingProgress() as display:
        display.start(label, steps)
        outcome = train_jax(
            spec,
            dirs,
            on_progress=lambda progress: display.update(label, progress),
            on_note=lambda text: display.note(label, text),
            overwrite=overwrite,
            command=invoked_command(),
        )
    if outcome.already_complete:
        console.print(f"{out_dir} already holds this finished training (pass --overwrite to train again)")
        return
    resumed = f", resumed at step {outcome.resumed_from:,}" if outcome.resumed_from else ""
    console.print(
        f"{algo.upper()} (jax): {len(spec.seeds)} model(s) × {outcome.steps_trained:,} steps in "
        f"{outcome.train_s:.1f} s after {outcome.compile_s:.1f} s of compilation "
        f"({outcome.steps_per_s:,.0f} env-steps/s over all seeds{resumed})"
    )
    for path in outcome.model_paths:
        console.print(f"model: {path}", soft_wrap=True)
