"""The JAX env's throughput-motivated formulations equal the plain ones.

``decode_action`` decodes one component at a time (instead of the (3,) vector) and
``overwrite_columns`` builds the observation as one concatenate (instead of chained
``.at[i].set``); both exist only because XLA's CPU backend runs them faster under ``vmap``
(docs/jax.md#throughput-bench-backend-jax). Here each is compared, vmapped over a batch, with
the formulation it replaces and, for the decode, with the numpy codec.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
pytest.importorskip("gymnax", reason="the JAX backend is optional: pip install -e '.[jax]'")


def special_actions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Actions in and out of [0, 1], a sixth of the components NaN or ±inf."""
    actions = rng.uniform(-0.5, 1.5, size=(n, 3)).astype(np.float32)
    special = rng.random((n, 3)) < 1 / 6
    actions[special] = rng.choice(np.array([np.nan, np.inf, -np.inf], dtype=np.float32), size=int(special.sum()))
    return actions


def vector_decode(action, params):
    """The env's decode before it worked per component: on the (3,) vector at once."""
    import jax.numpy as jnp

    u = jnp.fmin(jnp.fmax(jnp.asarray(action, jnp.float32).reshape(3), jnp.float32(0.0)), jnp.float32(1.0))
    market = jnp.maximum(u * params.width32, jnp.float32(0.0)) + params.lo32 * jnp.array([1, 1, 0], jnp.float32)
    a = jnp.minimum(jnp.maximum(market, params.action_lo), params.action_hi).astype(params.verified_mwh.dtype)
    scale = jnp.minimum(params.weights.max_total_allocation / (a[0] + a[1]), 1.0)
    return jnp.stack([a[0] * scale, a[1] * scale, a[2]]).astype(jnp.float32)


def test_componentwise_decode_equals_the_numpy_batch_decode(tiny_dataset) -> None:
    import jax

    from solarchain_eval.config import BenchmarkConfig
    from solarchain_eval.envs.jax_env import decode_action
    from solarchain_eval.jax import make_env_params
    from solarchain_eval.market.actions import ActionCodec

    params = make_env_params(tiny_dataset)
    codec = ActionCodec.from_config(BenchmarkConfig().market)
    actions = special_actions(np.random.default_rng(7), 4096)
    decoded = jax.jit(jax.vmap(decode_action, in_axes=(0, None)))(actions, params)
    got = np.stack([np.asarray(component) for component in decoded])  # (3, N) like decode_batch
    expected = codec.decode_batch(actions)
    assert got.dtype == np.float32 and got.shape == expected.shape
    # float32 scaling here, float64 in the numpy codec: the scaled components are rounded
    # twice in float32 (the scale, then the product), so they may be two float32 ulps apart
    np.testing.assert_array_max_ulp(got, expected, maxulp=2)
    # and bit for bit the (3,)-vector formulation it replaced
    vector = np.asarray(jax.jit(jax.vmap(vector_decode, in_axes=(0, None)))(actions, params)).T
    np.testing.assert_array_equal(got, vector)
    # the batch exercises every branch: clipped at both ends, scaled down, and untouched
    alpha, ell, burn = expected
    assert (alpha + ell > codec.max_total_allocation - 1e-6).any() and (alpha + ell < 0.9).any()
    assert (burn == 0).any() and (burn == np.float32(0.2)).any() and ((burn > 0) & (burn < 0.2)).any()


def test_componentwise_discrete_decode_reads_the_grid_row(tiny_dataset) -> None:
    import jax

    from solarchain_eval.envs.jax_env import decode_action
    from solarchain_eval.jax import make_env_params

    params = make_env_params(tiny_dataset, action_mode="discrete")
    table = np.asarray(params.discrete_actions)
    indices = np.arange(table.shape[0])
    decoded = jax.vmap(decode_action, in_axes=(0, None))(indices, params)
    np.testing.assert_array_equal(np.stack([np.asarray(c) for c in decoded], axis=1), table)


@pytest.mark.parametrize("indices", [(6, 7, 10, 11), (0,), (11,), (0, 1, 2), (3, 5, 9)])
def test_overwrite_columns_equals_chained_at_set(indices: tuple[int, ...]) -> None:
    import jax
    import jax.numpy as jnp

    from solarchain_eval.envs.jax_env import overwrite_columns

    rng = np.random.default_rng(len(indices) + sum(indices))
    rows = jnp.asarray(rng.normal(size=(64, 12)).astype(np.float32))
    values = jnp.asarray(rng.normal(size=(64, len(indices))).astype(np.float32))

    def plain(row, value):
        for j, index in enumerate(indices):
            row = row.at[index].set(value[j])
        return row

    def fast(row, value):
        return overwrite_columns(row, {index: value[j] for j, index in enumerate(indices)})

    expected = np.asarray(jax.vmap(plain)(rows, values))
    got = np.asarray(jax.jit(jax.vmap(fast))(rows, values))
    np.testing.assert_array_equal(got, expected)
    assert not np.array_equal(expected, np.asarray(rows))  # something was overwritten
