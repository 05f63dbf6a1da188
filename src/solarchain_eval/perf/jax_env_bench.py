"""Throughput of the JAX environment: ``jit(vmap)`` over many envs, ``lax.scan`` over steps."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..tasks.registry import DEFAULT_TASK
from .env_bench import Throughput, task_jax_env


def make_rollout(env: Any, params, num_envs: int, episodes: int):
    """A jitted function running ``episodes`` episodes in each of ``num_envs`` envs.

    Every episode starts with a vmapped reset (start hour and shocks drawn with ``jax.random``)
    followed by ``episode_steps`` vmapped steps; actions cycle through 8 precomputed batches,
    as in the numpy vector-env benchmark. Rewards and observations are summed so that nothing
    the env computes for the agent is optimised away.
    """
    steps = params.max_steps_in_episode
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

        # the env's float width: float64 under jax_enable_x64, else float32
        total = jnp.zeros((), jax.dtypes.canonicalize_dtype(jnp.float64))
        total, _ = jax.lax.scan(episode, total, jax.random.split(key, episodes))
        return total

    return jax.jit(run), episodes * steps * num_envs


def shard_rollout(env: Any, params, num_envs: int, episodes: int, devices: list):
    """:func:`make_rollout` with the envs split evenly over ``devices`` (``shard_map``).

    Each device runs ``num_envs / len(devices)`` envs with its own key; the function takes one
    key per device, (D,), and the (8, num_envs, 3) actions, and returns the devices' totals, (D,).
    On a CPU the devices are XLA host devices (``--xla_force_host_platform_device_count``), one
    per core: XLA runs one device's program on one thread, so this is how the scan uses them all.
    """
    count = len(devices)
    if num_envs % count:
        raise ValueError(f"{num_envs} envs cannot be split evenly over {count} devices")
    run, _ = make_rollout(env, params, num_envs // count, episodes)
    mesh = jax.sharding.Mesh(np.array(devices), ("envs",))
    spec = jax.sharding.PartitionSpec

    def per_device(keys: jax.Array, actions: jax.Array) -> jax.Array:
        return run(keys[0], actions)[None]

    sharded = jax.shard_map(
        per_device, mesh=mesh, in_specs=(spec("envs"), spec(None, "envs")), out_specs=spec("envs"), check_vma=False
    )
    return (
        jax.jit(sharded),
        jax.sharding.NamedSharding(mesh, spec(None, "envs")),
        episodes * params.max_steps_in_episode * num_envs,
    )


def jax_env_steps_per_s(
    data_dir: Path | None,
    num_envs: int,
    episodes: int,
    repeats: int,
    devices: int | None = None,
    task: str = DEFAULT_TASK,
) -> Throughput:
    """env-steps/s of the task's jitted, vmapped JAX env (compilation excluded, resets included).

    ``devices``: how many of JAX's devices to split the envs over (default: all of them).
    """
    env = task_jax_env(task, data_dir)
    params = env.default_params
    available = jax.devices()
    if devices is not None and not 1 <= devices <= len(available):
        raise ValueError(f"asked for {devices} JAX devices; {len(available)} available")
    used = available[:devices]
    run, actions_sharding, transitions = shard_rollout(env, params, num_envs, episodes, used)
    shape = env.action_space(params).shape
    actions = np.random.default_rng(1).random((8, num_envs, *shape), dtype=np.float32)
    actions = jax.device_put(actions, actions_sharding)

    def keys(seed: int) -> jax.Array:
        return jax.random.split(jax.random.key(seed), len(used))

    run(keys(0), actions).block_until_ready()  # compile
    samples = []
    for repeat in range(repeats):
        start = time.perf_counter()
        run(keys(repeat + 1), actions).block_until_ready()
        samples.append(transitions / (time.perf_counter() - start))
    platform = used[0].platform
    where = f"{len(used)} {platform} device{'s' if len(used) > 1 else ''}"
    return Throughput(
        f"JAX env on {where}, {num_envs} envs (jit, vmap, lax.scan; resets included)", "env-steps/s", tuple(samples)
    )
