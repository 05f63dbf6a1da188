"""The JAX throughput benchmark computes what a plain loop over the env computes.

``bench --backend jax`` times :func:`~solarchain_eval.perf.jax_env_bench.shard_rollout`: episodes of
vmapped resets and steps, the envs split over devices. Its result (the sum of every reward and
observation) is checked against one env at a time stepped from Python with the same keys and
actions, and the split over two CPU host devices (a subprocess: the device count is fixed when
JAX starts) against the same envs on one device.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
pytest.importorskip("gymnax", reason="the JAX backend is optional: pip install -e '.[jax]'")

NUM_ENVS, EPISODES = 4, 2


def loop_total(env, params, key, actions: np.ndarray, num_envs: int, episodes: int) -> float:
    """The rollout's total with one env at a time, in float64 on the host."""
    import jax

    total = 0.0
    for episode_key in jax.random.split(key, episodes):
        for index, env_key in enumerate(jax.random.split(episode_key, num_envs)):
            obs, state = env.reset_env(env_key, params)
            total += float(np.sum(np.asarray(obs, np.float64)))
            for k in range(params.episode_steps):
                obs, state, reward, _, _ = env.step_env(env_key, state, actions[k % actions.shape[0], index], params)
                total += float(reward) + float(np.sum(np.asarray(obs, np.float64)))
    return total


def test_rollout_equals_a_loop_over_single_envs(tiny_dataset: Path) -> None:
    import jax

    from solarchain_eval.jax import SolarChainJaxEnv, make_env_params
    from solarchain_eval.perf.jax_env_bench import make_rollout

    params = make_env_params(tiny_dataset)
    env = SolarChainJaxEnv(params)
    actions = np.random.default_rng(3).random((8, NUM_ENVS, 3), dtype=np.float32)
    run, transitions = make_rollout(env, params, NUM_ENVS, EPISODES)
    key = jax.random.key(11)
    total = float(run(key, actions))
    expected = loop_total(env, params, key, actions, NUM_ENVS, EPISODES)
    assert transitions == NUM_ENVS * EPISODES * params.episode_steps
    # float32 accumulation of a few hundred terms of magnitude <= ~10
    assert total == pytest.approx(expected, rel=1e-5)
    assert abs(expected) > 1.0  # the sum is not trivially zero


SHARDED = """
import json, sys
import jax, numpy as np
from solarchain_eval.jax import SolarChainJaxEnv, make_env_params
from solarchain_eval.perf.jax_env_bench import make_rollout, shard_rollout
params = make_env_params(sys.argv[1]); env = SolarChainJaxEnv(params)
devices = jax.devices()
actions = np.random.default_rng(3).random((8, 8, 3), dtype=np.float32)
run, sharding, transitions = shard_rollout(env, params, 8, 2, devices)
keys = jax.random.split(jax.random.key(5), len(devices))
sharded = [float(x) for x in run(keys, jax.device_put(actions, sharding))]
single, _ = make_rollout(env, params, 4, 2)
reference = [float(single(keys[d], actions[:, 4 * d : 4 * d + 4])) for d in range(2)]
print(json.dumps({"devices": len(devices), "sharded": sharded, "reference": reference, "transitions": transitions}))
"""


def test_split_over_two_host_devices_equals_one_device(tiny_dataset: Path) -> None:
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"}
    done = subprocess.run(
        [sys.executable, "-c", SHARDED, str(tiny_dataset)], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["devices"] == 2
    assert result["transitions"] == 8 * 2 * 24
    # each device ran its own half of the envs with its own key: the same programs as on one device
    assert result["sharded"] == pytest.approx(result["reference"], rel=1e-6)
    assert result["sharded"][0] != pytest.approx(result["sharded"][1], rel=1e-3)


def test_bench_cli_asks_for_one_host_device_per_core(monkeypatch: pytest.MonkeyPatch) -> None:
    from solarchain_eval.cli.bench import host_device_count

    monkeypatch.setitem(sys.modules, "jax", None)  # pretend JAX is not initialised yet
    del sys.modules["jax"]
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")
    assert host_device_count(3) == 3
    assert os.environ["XLA_FLAGS"] == "--xla_cpu_multi_thread_eigen=false --xla_force_host_platform_device_count=3"
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=1")
    host_device_count(None)  # the user's flag wins
    assert os.environ["XLA_FLAGS"] == "--xla_force_host_platform_device_count=1"
