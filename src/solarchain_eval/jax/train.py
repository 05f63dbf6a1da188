"""rejax training on the JAX environment: all seeds of one algorithm in one jitted ``vmap``.

Hyperparameters follow the SB3 reference (docs/training.md): learning rate, batch size and γ
from the config (3e-4, 64, 0.98), SB3's default network sizes and other defaults where rejax
has the same knob. The remaining differences between the libraries are listed in docs/jax.md.
Each seed's acting network (actor, or Q-network for DQN) is written to ``OUT/seed_<seed>/jax_model.msgpack`` with a
``train_config.json`` beside it (a policy adapter for ``evaluate`` is still to come).
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np
from flax import serialization

from ..config import BenchmarkConfig
from ..training import ACTION_MODES, dqn_learning_starts
from .env import EnvParams, SolarChainJaxEnv, make_env_params

JAX_MODEL_FILE = "jax_model.msgpack"
JAX_TRAIN_CONFIG_FILE = "train_config.json"


def rejax_config(algo: str, config: BenchmarkConfig, timesteps: int) -> dict[str, Any]:
    """rejax keyword arguments mirroring SB3's defaults plus the config's lr, batch and γ."""
    t = config.training
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
        n_steps = min(2048, int(timesteps))
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
            "buffer_size": min(1_000_000, int(timesteps)),
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
            "buffer_size": min(1_000_000, int(timesteps)),
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


def make_algo(algo: str, params: EnvParams, config: BenchmarkConfig, timesteps: int) -> Any:
    import rejax

    kwargs = rejax_config(algo, config, timesteps)
    return rejax.get_algo(algo).create(env=SolarChainJaxEnv(params), env_params=params, **kwargs)


@dataclass(frozen=True)
class JaxTrainOutcome:
    algo: str
    seeds: tuple[int, ...]
    timesteps: int
    compile_s: float
    train_s: float
    model_paths: tuple[Path, ...]

    @property
    def steps_per_s(self) -> float:
        """Env steps of all seeds per second of training (compilation excluded)."""
        return self.timesteps * len(self.seeds) / max(self.train_s, 1e-9)


def train_seeds(algo: str, seeds: tuple[int, ...], timesteps: int, params: EnvParams, config: BenchmarkConfig):
    """Train one model per seed in one jitted vmap; returns (train states, compile s, train s)."""
    instance = make_algo(algo, params, config, timesteps)
    keys = jax.vmap(jax.random.key)(np.asarray(seeds, dtype=np.uint32))
    train = jax.jit(jax.vmap(instance.train))
    start = time.perf_counter()
    compiled = train.lower(keys).compile()
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    states, _ = jax.block_until_ready(compiled(keys))
    return instance, states, compile_s, time.perf_counter() - start


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(fd, "wb") as handle:
        handle.write(data)
    os.replace(tmp, path)


def train_jax(
    algo: str,
    seeds: tuple[int, ...],
    timesteps: int,
    out_dir: Path,
    *,
    config: BenchmarkConfig | None = None,
    data_dir: Path | None = None,
    no_physics_penalty: bool = False,
) -> JaxTrainOutcome:
    """Train ``algo`` for every seed and write ``out_dir/seed_<s>/`` per seed."""
    cfg = config or BenchmarkConfig()
    if algo not in ACTION_MODES:
        raise ValueError(f"unknown algorithm {algo!r} (choose from ppo, sac, dqn)")
    params = make_env_params(
        data_dir, config=cfg, action_mode=ACTION_MODES[algo], no_physics_penalty=no_physics_penalty
    )
    _, states, compile_s, train_s = train_seeds(algo, seeds, timesteps, params, cfg)
    paths = []
    for i, seed in enumerate(seeds):
        network = states.q_ts.params if algo == "dqn" else states.actor_ts.params
        seed_dir = out_dir / f"seed_{seed}"
        # Only the acting network's parameters: what a policy adapter needs to act.
        _write_atomic(
            seed_dir / JAX_MODEL_FILE, serialization.to_bytes(jax.tree.map(lambda x, i=i: np.asarray(x[i]), network))
        )
        meta = {
            "identity": {
                "algo": algo,
                "backend": "jax",
                "seed": int(seed),
                "timesteps": int(timesteps),
                "no_physics_penalty": bool(no_physics_penalty),
                "data_dir": str(data_dir) if data_dir else None,
            },
            "rejax": rejax_config(algo, cfg, timesteps),
        }
        _write_atomic(seed_dir / JAX_TRAIN_CONFIG_FILE, json.dumps(meta, indent=2, default=list).encode())
        paths.append(seed_dir / JAX_MODEL_FILE)
    return JaxTrainOutcome(algo, tuple(seeds), int(timesteps), compile_s, train_s, tuple(paths))
