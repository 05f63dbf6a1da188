"""The SolarChain market as a functional gymnax environment.

The step is :func:`~solarchain_eval.market.dynamics.market_step` itself, run with
:data:`JAX_OPS` (the third arithmetic back-end next to ``SCALAR`` and ``BATCH`` of
:mod:`solarchain_eval.market.ops`), and ``info`` is built by the numpy env's
:func:`~solarchain_eval.envs.step_info.step_info`: one formula, three back-ends. Everything that depends
on the hourly table lives in :class:`EnvParams` as arrays; the reward weights, action mode
and episode length are static fields of the params (changing them recompiles).

Differences from the numpy env (see docs/jax.md): start hours and price shocks come from
``jax.random`` instead of numpy's generator (:meth:`SolarChainJaxEnv.reset_to` takes them
explicitly, which the equality tests use); without ``jax_enable_x64`` the arithmetic is
float32; a discrete index outside the grid is clipped instead of raising.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from gymnax.environments import environment, spaces

from ..config import BenchmarkConfig
from ..data.table import HourlyTable
from ..market.actions import ActionCodec, initial_action
from ..market.dynamics import RewardWeights, market_step
from ..market.observation import OBS_LIMIT, OBS_LIQUIDITY, OBS_PREV_ALPHA, OBS_PREV_ELL, OBS_PRICE, OBSERVATION_SHAPE
from ..market.spaces import ACTION_HIGH, ACTION_LOW, ACTION_SHAPE
from .market_setup import env_config, market_inputs, resolve_table, start_hours
from .rng_stream import PRICE_NOISE_STD
from .step_info import step_info


class JaxOps:
    """jax.numpy back-end of the market functions, written for one env (``vmap`` batches it).

    Per-city values are tuples of scalars, as in ``SCALAR``: under ``vmap`` every city's value is
    then its own contiguous (N,) vector, which XLA's CPU backend vectorises; a (C,) array per env
    would become an (N, C) array read with stride C (measured: 1.5x fewer env-steps/s).
    """

    maximum = staticmethod(jnp.maximum)
    minimum = staticmethod(jnp.minimum)

    @staticmethod
    def clip(x: Any, lo: float, hi: float) -> Any:
        return jnp.minimum(jnp.maximum(x, lo), hi)

    @staticmethod
    def per_city(formula: Any, per_env: tuple, city_columns: tuple) -> tuple:
        """``formula(a, b, share, trust)`` for each city; a tuple of scalars."""
        a, b = per_env
        shares, trusts = city_columns
        return tuple(formula(a, b, share, trust) for share, trust in zip(shares, trusts, strict=True))

    @staticmethod
    def city_variance(city_values: tuple) -> Any:
        """Population variance over cities, summed left to right like numpy below 8 items."""
        n = len(city_values)
        if n == 0:
            return jnp.zeros(())
        if n >= 8:  # numpy's pairwise order differs from here on; the difference is an ulp
            stacked = jnp.stack(city_values)
            deviation = stacked - jnp.sum(stacked) / n
            return jnp.sum(deviation * deviation) / n
        total = city_values[0]
        for value in city_values[1:]:
            total = total + value
        mean = total / n
        first = city_values[0] - mean
        total = first * first
        for value in city_values[1:]:
            deviation = value - mean
            total = total + deviation * deviation
        return total / n


JAX_OPS = JaxOps()


@struct.dataclass
class EnvState(environment.EnvState):
    """One market: the episode's start hour and shocks, pool, price, previous action.

    ``time`` (gymnax's step counter) is the step index k within the episode.
    """

    start: jax.Array
    noise: jax.Array  # (episode_steps,) price shocks, already scaled by 0.004
    liquidity: jax.Array
    peak_liquidity: jax.Array
    token_price: jax.Array
    peak_price: jax.Array
    prev_action: tuple  # executed (α, ℓ, b), three float32 scalars (see decode_action)
    city_totals: jax.Array  # (C,) reward tokens per city this episode


@struct.dataclass
class EnvParams:
    """Hourly inputs as arrays (H hours, C cities) plus static settings."""

    verified_mwh: jax.Array
    reported_mwh: jax.Array
    unsafe_supply_mwh: jax.Array
    clearing_demand_mwh: jax.Array
    raw_violation_rate: jax.Array
    city_share: jax.Array  # (H, C)
    city_trust: jax.Array  # (H, C)
    obs_template: jax.Array  # (H, 12) float32
    # (5 + 2C, H): G_v, X, Q_c, G_r, ν, then each city's share and trust; one row per quantity, so
    # the step gathers each quantity from a contiguous row (vmapped: a contiguous (N,) vector).
    hour_columns: jax.Array
    start_hours: jax.Array  # admissible starts (midnights)
    discrete_actions: jax.Array  # (levels**3, 3) float32 executed actions
    action_lo: jax.Array  # (3,) float32 sanitising bounds (the ranges rounded to float32)
    action_hi: jax.Array
    lo32: jax.Array  # (3,) float32 decoding constants
    width32: jax.Array
    initial_action: jax.Array  # (3,) float32
    weights: RewardWeights = struct.field(pytree_node=False, default=None)
    action_mode: str = struct.field(pytree_node=False, default="continuous")
    episode_steps: int = struct.field(pytree_node=False, default=24)
    initial_liquidity: float = struct.field(pytree_node=False, default=0.0)
    initial_price: float = struct.field(pytree_node=False, default=1.0)
    depth_scale: float = struct.field(pytree_node=False, default=1.0)

    @property
    def max_steps_in_episode(self) -> int:
        """gymnax's name for the episode length (rejax's evaluation reads it)."""
        return self.episode_steps


def float_dtype() -> Any:
    """float64 when ``jax_enable_x64`` is on, else float32."""
    return jnp.float64 if jax.config.jax_enable_x64 else jnp.float32


def make_env_params(
    data_dir: str | Path | None = None,
    *,
    config: BenchmarkConfig | str | Path | None = None,
    no_physics_penalty: bool | None = None,
    action_mode: str | None = None,
    table: HourlyTable | None = None,
) -> EnvParams:
    """Params for a dataset and config; the same arguments as ``SolarChainEnv``."""
    cfg = env_config(config, no_physics_penalty=no_physics_penalty, action_mode=action_mode)
    table = table if table is not None else resolve_table(None if data_dir is None else data_dir, cfg)
    hours, template = market_inputs(table)
    codec = ActionCodec.from_config(cfg.market)
    m = cfg.market
    f = float_dtype()
    f32 = np.float32
    return EnvParams(
        verified_mwh=jnp.asarray(table.verified_mwh, f),
        reported_mwh=jnp.asarray(table.reported_mwh, f),
        unsafe_supply_mwh=jnp.asarray(hours.unsafe_supply_mwh, f),
        clearing_demand_mwh=jnp.asarray(hours.clearing_demand_mwh, f),
        raw_violation_rate=jnp.asarray(table.raw_violation_rate, f),
        city_share=jnp.asarray(hours.city_share, f),
        city_trust=jnp.asarray(hours.city_trust, f),
        obs_template=jnp.asarray(template, jnp.float32),
        hour_columns=jnp.asarray(
            np.vstack(
                [
                    table.verified_mwh,
                    hours.unsafe_supply_mwh,
                    hours.clearing_demand_mwh,
                    table.reported_mwh,
                    table.raw_violation_rate,
                    hours.city_share.T,
                    hours.city_trust.T,
                ]
            ),
            f,
        ),
        start_hours=jnp.asarray(
            start_hours(table.hours, cfg.episode_steps, cfg.start_days, str(table.source)), jnp.int32
        ),
        discrete_actions=jnp.asarray(np.array(codec.discrete_table(cfg.discrete_levels), dtype=f32)),
        action_lo=jnp.asarray(codec.lo32, jnp.float32),
        action_hi=jnp.asarray(codec.hi32, jnp.float32),
        lo32=jnp.asarray(codec.lo32, jnp.float32),
        width32=jnp.asarray(codec.width32, jnp.float32),
        initial_action=jnp.asarray(np.array(initial_action(m), dtype=f32)),
        weights=RewardWeights.from_config(cfg),
        action_mode=cfg.action_mode,
        episode_steps=cfg.episode_steps,
        initial_liquidity=m.initial_liquidity,
        initial_price=m.initial_token_price,
        depth_scale=max(m.initial_liquidity, 1e-9),
    )


def decode_action(action: Any, params: EnvParams) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Executed (α, ℓ, b) as three float32 scalars; mirrors ``ActionCodec.decode_batch``.

    Decoded one component at a time, as ``ActionCodec.decode`` does: under ``vmap`` each
    component is then its own (N,) vector. Decoding the (3,) vector instead made XLA work on
    (N, 3) arrays read with stride 3 and recompute them in every fusion that used the action
    (measured: 1.38x fewer env-steps/s; docs/jax.md).
    """
    if params.action_mode == "discrete":
        index = jnp.asarray(action).reshape(-1)[0].astype(jnp.int32)
        row = jnp.take(params.discrete_actions, index, axis=0, mode="clip")
        return row[0], row[1], row[2]
    u = jnp.asarray(action, jnp.float32).reshape(3)
    f = params.verified_mwh.dtype  # the working float type: float64 with x64, as in the numpy codec
    market = []
    for i in range(3):
        # fmax/fmin ignore NaN: NaN -> 0, -inf -> 0, +inf -> 1, as in the numpy codec.
        u_i = jnp.fmin(jnp.fmax(u[i], jnp.float32(0.0)), jnp.float32(1.0))
        # numpy rounds the product and the sum separately; XLA's CPU backend would contract them
        # into one FMA (one rounding). The max with 0 (the product is >= 0 anyway) keeps them apart.
        product = jnp.maximum(u_i * params.width32[i], jnp.float32(0.0))
        value = product + params.lo32[i] if i < 2 else product  # the burn rate has no offset
        # Sanitise: clip in float32 (the original's np.clip on a float32 scalar), scale in the
        # working float type (float64 in the numpy codec and with x64).
        market.append(jnp.minimum(jnp.maximum(value, params.action_lo[i]), params.action_hi[i]).astype(f))
    alpha, ell, burn = market
    scale = jnp.minimum(params.weights.max_total_allocation / (alpha + ell), 1.0)
    return (alpha * scale).astype(jnp.float32), (ell * scale).astype(jnp.float32), burn.astype(jnp.float32)


def action_jitter(executed: tuple, prev: tuple) -> jax.Array:
    """J = |a - a_prev|_1 in float32, summed left to right (``action_jitter_f32_batch``)."""
    return (jnp.abs(executed[0] - prev[0]) + jnp.abs(executed[1] - prev[1])) + jnp.abs(executed[2] - prev[2])


def overwrite_columns(row: jax.Array, values: dict[int, jax.Array]) -> jax.Array:
    """``row`` with ``row[i]`` replaced by ``values[i]``, built as one concatenate.

    ``row.at[i].set(v)`` becomes, under ``vmap``, a select over the whole (N, len(row)) array
    that XLA evaluates for every element: each value's formula ran once per column (measured:
    the concatenate is 1.28x faster).
    """
    pieces, start = [], 0
    for index in sorted(values):
        pieces += [row[start:index], jnp.reshape(values[index], (1,))]
        start = index + 1
    return jnp.concatenate([*pieces, row[start:]])


class SolarChainJaxEnv(environment.Environment[EnvState, EnvParams]):
    """gymnax environment of the SolarChain market: 24 hourly decisions per episode.

    Parameters
    ----------
    params : EnvParams, optional
        Default params (``make_env_params()`` on the embedded default dataset when omitted).

    Notes
    -----
    ``step`` auto-resets after the last hour (gymnax convention) and returns ``done`` = True
    there; episodes truncate, they never terminate. ``info`` holds the numpy env's per-step
    quantities (``cost`` = V + A included), ``city_rewards`` (C,), ``truncated`` (= ``done``)
    and ``terminal_obs``: the observation after the step before any auto-reset (the step's
    own observation when the episode goes on).
    """

    def __init__(self, params: EnvParams | None = None) -> None:
        super().__init__()
        self._params = params

    @property
    def default_params(self) -> EnvParams:
        if self._params is None:
            self._params = make_env_params()
        return self._params

    @property
    def name(self) -> str:
        return "SolarChain-v0"

    @property
    def num_actions(self) -> int:
        return int(self.default_params.discrete_actions.shape[0])

    def action_space(self, params: EnvParams | None = None) -> spaces.Space:
        params = self.default_params if params is None else params
        if params.action_mode == "discrete":
            return spaces.Discrete(int(params.discrete_actions.shape[0]))
        return spaces.Box(ACTION_LOW, ACTION_HIGH, ACTION_SHAPE, jnp.float32)

    def observation_space(self, params: EnvParams | None = None) -> spaces.Box:
        return spaces.Box(-OBS_LIMIT, OBS_LIMIT, OBSERVATION_SHAPE, jnp.float32)

    # --- functional core --------------------------------------------------------------------
    def reset_to(self, start: Any, noise: Any, params: EnvParams) -> tuple[jax.Array, EnvState]:
        """Start an episode at ``start`` with the given (already scaled) price shocks."""
        f = params.verified_mwh.dtype
        n_hours = params.verified_mwh.shape[0]
        start = jnp.clip(jnp.asarray(start, jnp.int32), 0, max(n_hours - params.episode_steps, 0))
        state = EnvState(
            time=jnp.zeros((), jnp.int32),
            start=start,
            noise=jnp.asarray(noise, f),
            liquidity=jnp.asarray(params.initial_liquidity, f),
            peak_liquidity=jnp.asarray(params.initial_liquidity, f),
            token_price=jnp.asarray(params.initial_price, f),
            peak_price=jnp.asarray(params.initial_price, f),
            prev_action=tuple(params.initial_action[i] for i in range(3)),
            city_totals=jnp.zeros(params.city_share.shape[1], f),
        )
        return self.get_obs(state, params), state

    def reset_env(self, key: jax.Array, params: EnvParams) -> tuple[jax.Array, EnvState]:
        key_start, key_noise = jax.random.split(key)
        index = jax.random.randint(key_start, (), 0, params.start_hours.shape[0])
        f = params.verified_mwh.dtype
        noise = jax.random.normal(key_noise, (params.episode_steps,), f) * PRICE_NOISE_STD
        return self.reset_to(params.start_hours[index], noise, params)

    def get_obs(self, state: EnvState, params: EnvParams | None = None, key: Any = None) -> jax.Array:
        params = self.default_params if params is None else params
        hour = jnp.minimum(state.start + state.time, params.verified_mwh.shape[0] - 1)
        values = {
            OBS_LIQUIDITY: jnp.minimum(state.liquidity, OBS_LIMIT).astype(jnp.float32),
            OBS_PRICE: jnp.minimum(state.token_price, OBS_LIMIT).astype(jnp.float32),
            OBS_PREV_ALPHA: state.prev_action[0],
            OBS_PREV_ELL: state.prev_action[1],
        }
        return overwrite_columns(params.obs_template[hour], values)

    def is_terminal(self, state: EnvState, params: EnvParams) -> jax.Array:
        return state.time >= params.episode_steps

    def step_env(
        self, key: jax.Array, state: EnvState, action: Any, params: EnvParams
    ) -> tuple[jax.Array, EnvState, jax.Array, jax.Array, dict[str, Any]]:
        executed32 = decode_action(action, params)
        f = params.verified_mwh.dtype
        executed = tuple(component.astype(f) for component in executed32)
        k = jnp.minimum(state.time, params.episode_steps - 1)
        hour = jnp.minimum(state.start + k, params.verified_mwh.shape[0] - 1)
        row = tuple(column[hour] for column in params.hour_columns)
        n_cities = params.city_share.shape[1]
        # The same call as SolarChainEnv.step / SolarChainVectorEnv._advance.
        out = market_step(
            JAX_OPS,
            params.weights,
            row[0],
            row[1],
            row[2],
            row[5 : 5 + n_cities],
            row[5 + n_cities :],
            state.liquidity,
            state.peak_liquidity,
            state.token_price,
            state.peak_price,
            executed,
            action_jitter(executed32, state.prev_action).astype(f),
            state.noise[k],
        )
        city_rewards = jnp.stack(out.city_rewards) if n_cities else jnp.zeros(0, f)
        state = state.replace(
            time=state.time + 1,
            liquidity=out.liquidity,
            peak_liquidity=out.peak_liquidity,
            token_price=out.token_price,
            peak_price=out.peak_price,
            prev_action=executed32,
            city_totals=state.city_totals + city_rewards,
        )
        inputs = (row[0], row[3], row[1], row[4], row[2])
        info = step_info(out, executed, hour, state.start, inputs, params.depth_scale)
        info["step"] = k
        info["city_rewards"] = city_rewards
        done = self.is_terminal(state, params)
        # The barrier makes the observation read the new state from memory; without it XLA
        # recomputes the price formula inside the observation's fusion (measured: 1.06x).
        obs = self.get_obs(jax.lax.optimization_barrier(state), params)
        # gymnax's step replaces obs by the reset one after the last hour; keep the true last obs
        # and say that the episode was cut by the time limit, so that training can bootstrap
        # there as SB3 does (jax/alignment.py). Episodes never terminate, they only truncate.
        info["terminal_obs"] = obs
        info["truncated"] = done
        return obs, state, out.reward, done, info
