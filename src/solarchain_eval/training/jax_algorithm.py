"""The rejax algorithm of one JAX training: its SB3-aligned settings, built and compiled.

:func:`make_algo` builds the rejax algorithm (SB3-aligned, :func:`~.jax_alignment.sb3_variant`)
with the settings of :func:`rejax_config`; :func:`compile_training` compiles rejax's own
``train`` over the seeds' keys. The trainer (:mod:`.jax_trainer`) and its chunked runner
(:mod:`.jax_chunks`) both build on these, so neither imports the other's upper half.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import jax
import numpy as np

from ..common.cache import cache_dir
from ..config import BenchmarkConfig
from .jax_alignment import sb3_variant
from .sb3_spec import dqn_learning_starts


def rejax_config(
    algo: str, config: BenchmarkConfig, timesteps: int, buffer_timesteps: int | None = None
) -> dict[str, Any]:
    """rejax keyword arguments mirroring SB3's defaults plus the config's lr, batch and γ.

    SAC's and DQN's replay buffer holds SB3's 1e6 transitions, or all of a shorter training's;
    ``buffer_timesteps`` sizes it for a training of that many steps instead (``bench-train``
    times short trainings with the paper's buffer).
    """
    t = config.training
    buffer_size = min(1_000_000, int(buffer_timesteps or timesteps))
    common = {
        "learning_rate": t.learning_rate,
        "gamma": t.gamma,
        "total_timesteps": int(timesteps),
        "eval_freq": int(timesteps),
        "skip_initial_evaluation": True,
    }
    if algo == "ppo":
        # SB3 PPO: n_steps 2048, n_epochs 10, minibatches of batch_size, ent 0, clip 0.2, grad norm 0.5,
        # separate 64x64 tanh actor and critic.
        n_steps = 2048  # SB3 collects whole 2,048-step rollouts even for smaller budgets
        return {
            **common,
            "num_envs": 1,
            "num_steps": n_steps,
            "num_epochs": 10,
            "num_minibatches": max(1, n_steps // t.batch_size),
            "gae_lambda": 0.95,
            "clip_eps": 0.2,
            "vf_coef": 0.5,
            "ent_coef": 0.0,
            "max_grad_norm": 0.5,
            "agent_kwargs": {"activation": "tanh", "hidden_layer_sizes": (64, 64)},
        }  # rejax PPO reads sizes here
    if algo == "sac":
        # SB3 SAC: 256x256 ReLU, buffer 1e6, learning_starts 100, tau 0.005, one update per step.
        return {
            **common,
            "num_envs": 1,
            "batch_size": t.batch_size,
            "buffer_size": buffer_size,
            "fill_buffer": 100,
            "polyak": 0.995,
            "target_update_freq": 1,
            "num_epochs": 1,
            "hidden_layer_sizes": (256, 256),
            "agent_kwargs": {"activation": "relu"},
        }
    if algo == "dqn":
        # SB3 DQN: 64x64 ReLU, train_freq 4 (here: 4 envs per iteration, one update), hard target
        # update every 10,000 steps, eps 1 -> 0.05 over 10 %, grad norm 10, no double DQN.
        return {
            **common,
            "num_envs": 4,
            "batch_size": t.batch_size,
            "buffer_size": buffer_size,
            "fill_buffer": max(dqn_learning_starts(timesteps), t.batch_size),
            "polyak": 0.0,
            "target_update_freq": 10_000,
            "num_epochs": 1,
            "eps_start": 1.0,
            "eps_end": 0.05,
            "exploration_fraction": 0.1,
            "max_grad_norm": 10.0,
            "ddqn": False,
            "agent_kwargs": {"activation": "relu"},
        }  # rejax fixes DQN at 64x64, SB3's size
    raise ValueError(f"unknown algorithm {algo!r} (choose from ppo, sac, dqn)")


def iteration_steps(algo: str, settings: dict[str, Any]) -> int:
    """Env steps per rejax training iteration (all of one seed's parallel envs)."""
    return int(settings["num_envs"]) * (int(settings["num_steps"]) if algo == "ppo" else 1)


def progress_chunks(iterations: int, most: int = 10) -> int:
    """The largest divisor of ``iterations`` up to ``most``: blocks of rejax's ``train`` that keep the step count exact."""
    return max(k for k in range(1, min(most, iterations) + 1) if iterations % k == 0)


def make_algo(algo: str, env: Any, config: BenchmarkConfig, timesteps: int, buffer_timesteps: int | None = None) -> Any:
    """The rejax algorithm (SB3-aligned, :func:`~.jax_alignment.sb3_variant`) for ``timesteps`` steps
    on ``env``, a task's JAX env (:func:`~solarchain_eval.tasks.base.make_jax_env`) with its ``default_params``.

    rejax's own ``train`` runs ``ceil(total / eval_freq)`` blocks of ``ceil(eval_freq / iteration)``
    iterations with an evaluation callback after each; ``eval_freq`` is set to a whole number of
    iterations so that the blocks add up to exactly SB3's step count, and the callback does nothing.
    The backend's trainer runs the iterations in chunks instead (:mod:`.jax_chunks`).
    """
    import jax.numpy as jnp

    settings = rejax_config(algo, config, timesteps, buffer_timesteps)
    per_iteration = iteration_steps(algo, settings)
    iterations = -(-int(timesteps) // per_iteration)
    settings["eval_freq"] = iterations // progress_chunks(iterations) * per_iteration
    instance = sb3_variant(algo).create(env=env, env_params=env.default_params, **settings)
    return instance.replace(eval_callback=lambda algo_instance, ts, rng: jnp.zeros(()))


def use_compilation_cache() -> None:
    """Keep compiled training programs on disk (unless ``JAX_COMPILATION_CACHE_DIR`` says where already).

    Every seed and every rerun of one algorithm and setting compiles the same program (the seeds'
    keys are its arguments), so a grid's second train unit of a kind loads it instead of compiling.
    """
    if not jax.config.jax_compilation_cache_dir:
        jax.config.update("jax_compilation_cache_dir", str(cache_dir() / "jax-compilation"))


def compile_training(
    algo: str,
    seeds: tuple[int, ...],
    timesteps: int,
    env: Any,
    config: BenchmarkConfig,
    buffer_timesteps: int | None = None,
) -> tuple[Any, float]:
    """rejax's own ``train`` as one program, ``jit(vmap(train))`` over the seeds' keys, compiled;
    returns (compiled function, compile s). ``bench-train`` times it; the trainer runs
    :class:`~.jax_chunks.ChunkedTraining`."""
    use_compilation_cache()
    instance = make_algo(algo, env, config, timesteps, buffer_timesteps)
    keys = seed_keys(seeds)
    start = time.perf_counter()
    with warnings.catch_warnings():
        # rejax asks for int64 indices, which JAX truncates to int32 without x64: harmless here.
        warnings.filterwarnings("ignore", message="Explicitly requested dtype int64")
        compiled = jax.jit(jax.vmap(instance.train)).lower(keys).compile()
    return compiled, time.perf_counter() - start


def seed_keys(seeds: tuple[int, ...]) -> jax.Array:
    return jax.vmap(jax.random.key)(np.asarray(seeds, dtype=np.uint32))
