"""SAC's and DQN's replay minibatches in the JAX backend: SB3's sampling (uniform, with
replacement, among the stored transitions) at a cost that does not grow with the buffer."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
pytest.importorskip("rejax", reason="the JAX backend is optional: pip install -e '.[jax]'")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from gymnax.environments import spaces  # noqa: E402
from rejax.buffers import Minibatch  # noqa: E402

from solarchain_eval.training.jax_replay import SB3ReplayBuffer  # noqa: E402

SIZE = 1000


def _buffer(stored: int, size: int = SIZE) -> SB3ReplayBuffer:
    """A buffer whose ``stored`` transitions have obs[0] = 1, 2, ..., stored (empty rows are 0)."""
    buffer = SB3ReplayBuffer.empty(size, spaces.Box(-1e9, 1e9, (4,)), spaces.Box(0.0, 1.0, (3,)))
    for first in range(1, stored + 1, size):  # rejax's extend takes at most a buffer's worth at once
        rows = jnp.arange(first, min(first + size, stored + 1), dtype=jnp.float32)
        batch = Minibatch(
            obs=jnp.tile(rows[:, None], (1, 4)),
            action=jnp.zeros((rows.size, 3)),
            reward=rows,
            done=jnp.zeros(rows.size, dtype=bool),
            next_obs=jnp.tile(rows[:, None], (1, 4)) + 0.5,
        )
        buffer = buffer.extend(batch)
    return buffer


def test_minibatches_come_from_the_stored_transitions_with_replacement():
    """64 draws from 5 stored rows: only those rows, whole transitions, repeats allowed (SB3's
    ``randint``); rejax's draw without replacement returns never-written rows here."""
    buffer = _buffer(5)
    counts = np.zeros(6)
    for i in range(200):
        batch = buffer.sample(64, jax.random.key(i))
        obs = np.asarray(batch.obs)
        assert set(np.unique(obs)) <= {1.0, 2.0, 3.0, 4.0, 5.0}
        np.testing.assert_array_equal(np.asarray(batch.reward), obs[:, 0])  # rows stay whole
        np.testing.assert_array_equal(np.asarray(batch.next_obs), obs + 0.5)
        counts += np.bincount(obs[:, 0].astype(int), minlength=6)
    share = counts[1:] / counts.sum()
    np.testing.assert_allclose(share, 0.2, atol=0.01)  # uniform: 12,800 draws, σ of a share ≈ 0.0035


def test_a_full_buffer_is_sampled_over_all_its_rows():
    """Once the write position wraps, SB3's upper bound is the buffer's size."""
    buffer = _buffer(SIZE + 250, size=SIZE)  # rows 251..1250 remain
    assert bool(buffer.full) and int(buffer.index) == 250
    drawn = np.concatenate([np.asarray(buffer.sample(64, jax.random.key(i)).reward) for i in range(200)])
    assert drawn.min() >= 251 and drawn.max() <= 1250
    assert np.unique(drawn).size > 0.9 * SIZE  # 12,800 draws reach nearly every row, not just the first 250
    assert drawn.min() < 300 and drawn.max() > 1200


def _intermediate_sizes(jaxpr) -> list[int]:
    sizes = []
    for eqn in jaxpr.eqns:
        sizes += [int(np.prod(v.aval.shape)) for v in eqn.outvars if hasattr(v.aval, "shape")]
        for param in eqn.params.values():
            inner = getattr(param, "jaxpr", None)
            if inner is not None:
                sizes += _intermediate_sizes(getattr(inner, "jaxpr", inner))
    return sizes


def test_sampling_work_does_not_grow_with_the_buffer():
    """No array the sample computes is as long as the buffer (rejax's builds several: a
    probability per row, then a draw over them), so an update costs the same at 300,000 rows."""
    buffer = _buffer(10)
    jaxpr = jax.make_jaxpr(lambda b, key: b.sample(64, key))(buffer, jax.random.key(0))
    sizes = _intermediate_sizes(jaxpr.jaxpr)
    assert sizes and max(sizes) <= 64 * 4  # the gathered obs (64 × 4) is the largest


@pytest.mark.parametrize("algo", ["sac", "dqn"])
def test_sac_and_dqn_train_states_hold_the_sb3_buffer(tiny_dataset, algo):
    from solarchain_eval.config import BenchmarkConfig
    from solarchain_eval.envs.jax_env import SolarChainJaxEnv, make_env_params
    from solarchain_eval.training.jax_algorithm import make_algo, rejax_config
    from solarchain_eval.training.jax_alignment import REPLAY_SAMPLING, SB3_ALIGNMENT

    params = make_env_params(tiny_dataset, action_mode="discrete" if algo == "dqn" else "continuous")
    instance = make_algo(algo, SolarChainJaxEnv(params), BenchmarkConfig(), 500, buffer_timesteps=300_000)
    state = instance.init_state(jax.random.key(0))
    assert type(state.replay_buffer) is SB3ReplayBuffer and state.replay_buffer.size == 300_000
    assert SB3_ALIGNMENT[algo]["replay_sampling"] == REPLAY_SAMPLING
    assert rejax_config(algo, BenchmarkConfig(), 500)["buffer_size"] == 500
    assert rejax_config(algo, BenchmarkConfig(), 2_000_000)["buffer_size"] == 1_000_000  # SB3's
