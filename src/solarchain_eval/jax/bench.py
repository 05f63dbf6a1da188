"""Throughput of the JAX environment: ``jit(vmap)`` over many envs, ``lax.scan`` over steps."""

from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..bench import Throughput
from .env import SolarChainJaxEnv, make_env_params


def make_rollout(env: SolarChainJaxEnv, params, num_envs: int, episodes: int):
    """A jitted function running ``episodes`` episodes in each of ``num_envs`` envs.

    Every episode starts with a vmapped reset (start hour and shocks drawn with ``jax.random``)
    followed by ``episode_steps`` vmapped steps; actions cycle through 8 precomputed batches,
    as in the numpy vector-env benchmark. Rewards and observations are summed so that nothing
    the env computes for the agent is optimised away.
    """
    steps = params.episode_steps
    reset = jax.vmap(env.reset_env, in_axes=(0, None))
    step = jax.vmap(env.step_env, in_axes=(None, 0, 0, None))

    def run(key: jax.Array, actions: jax.Array) -> jax.Array:
        def episode(carry, key):
            total = carry
            obs, state = reset(jax.random.split(key, num_envs), params)

            def one(inner, k):
                state, total = inner
                obs, state, reward, _, _ = step(key, state, actions[k % actions.shape[0]], params)
                return (state, total + jnp.sum(reward) + jnp.sum(obs)), None

            (state, total), _ = jax.lax.scan(one, (state, total + jnp.sum(obs)), jnp.arange(steps))
            return total, None

        total, _ = jax.lax.scan(episode, jnp.zeros((), params.verified_mwh.dtype), jax.random.split(key, episodes))
        return total

    return jax.jit(run), episodes * steps * num_envs


def jax_env_steps_per_s(data_dir: Path, num_envs: int, episodes: int, repeats: int) -> Throughput:
    """env-steps/s of the jitted, vmapped JAX env (compilation excluded, resets included)."""
    params = make_env_params(data_dir)
    env = SolarChainJaxEnv(params)
    run, transitions = make_rollout(env, params, num_envs, episodes)
    actions = jnp.asarray(np.random.default_rng(1).random((8, num_envs, 3), dtype=np.float32))
    run(jax.random.key(0), actions).block_until_ready()  # compile
    samples = []
    for repeat in range(repeats):
        start = time.perf_counter()
        run(jax.random.key(repeat + 1), actions).block_until_ready()
        samples.append(transitions / (time.perf_counter() - start))
    device = jax.devices()[0].platform
    return Throughput(
        f"JAX env on {device}, {num_envs} envs (jit, vmap, lax.scan; resets included)", "env-steps/s", tuple(samples)
    )
