"""What every solar market env back-end is built from: its configuration (:func:`env_config`), its
dataset (:func:`resolve_table`) and the per-table inputs derived once (:func:`setup_market`,
:func:`market_inputs`, :func:`start_hours`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..config import BenchmarkConfig, check_episode_fits, load_config, select_starts
from ..data.default import resolve_data_dir
from ..data.table import HourlyTable, load_table
from ..market.actions import ActionCodec, DiscreteActions, check_action_mode, initial_action
from ..market.dynamics import MarketHours, RewardWeights
from ..market.observation import OBSERVATION_NAMES, observation_template
from ..market.spaces import action_space, observation_space


def resolve_config(config: BenchmarkConfig | str | Path | None) -> BenchmarkConfig:
    if config is None:
        return BenchmarkConfig()
    if isinstance(config, BenchmarkConfig):
        return config
    return load_config(config)


def resolve_table(data_dir: str | Path | None, config: BenchmarkConfig) -> HourlyTable:
    """Explicit ``data_dir``, else the config's, else the embedded default dataset."""
    return load_table(resolve_data_dir(data_dir, config.data_dir))


def env_config(
    config: BenchmarkConfig | str | Path | None,
    *,
    no_physics_penalty: bool | None,
    action_mode: str | None,
    episode_steps: int | None = None,
) -> BenchmarkConfig:
    """The configuration an env runs with: the one argument validation of every env constructor.

    ``config`` (default ``BenchmarkConfig()``) with the constructor's overrides applied; an
    unknown ``action_mode`` is a ValueError.
    """
    cfg = resolve_config(config).with_updates(
        action_mode=check_action_mode(action_mode), no_physics_penalty=no_physics_penalty
    )
    if episode_steps is not None:
        cfg = cfg.with_updates(episode_steps=episode_steps)
    return cfg


def setup_market(
    env: Any,
    data_dir: str | Path | None,
    config: BenchmarkConfig | str | Path | None,
    *,
    no_physics_penalty: bool | None,
    action_mode: str | None,
    table: HourlyTable | None,
    episode_steps: int | None = None,
) -> None:
    """Set the attributes :class:`SolarChainEnv` and the vector env share, from their arguments.

    ``config``, ``table``, ``market_hours``, ``codec``, ``weights``, ``action_mode``,
    ``episode_steps``, ``cities``, ``observation_names``, ``single_observation_space`` and
    ``single_action_space``, plus the derived per-table inputs (start hours, observation
    template, the discrete action table, the initial previous action).
    """
    cfg = env_config(
        config, no_physics_penalty=no_physics_penalty, action_mode=action_mode, episode_steps=episode_steps
    )
    env.config = cfg
    env.table = table if table is not None else resolve_table(data_dir, cfg)
    check_episode_fits(cfg, env.table.hours, str(env.table.source))
    env.market_hours, env._obs_template = market_inputs(env.table)
    env.codec = ActionCodec.from_config(cfg.market)
    env.weights = RewardWeights.from_config(cfg)
    env.action_mode = cfg.action_mode
    env.episode_steps = cfg.episode_steps
    env.cities = env.table.cities
    env.observation_names = OBSERVATION_NAMES
    env._n_hours = env.table.hours
    env._starts = start_hours(env.table.hours, cfg.episode_steps, cfg.start_days, str(env.table.source))
    env._depth_scale = max(cfg.market.initial_liquidity, 1e-9)
    env._initial_action = initial_action(cfg.market)
    env.single_observation_space = observation_space()
    env.single_action_space = action_space(cfg.action_mode, cfg.discrete_levels)
    env._discrete_actions = (
        DiscreteActions.from_codec(env.codec, cfg.discrete_levels) if cfg.action_mode == "discrete" else None
    )


_HOURS_CACHE: dict[int, tuple[HourlyTable, MarketHours, np.ndarray]] = {}


def market_inputs(table: HourlyTable) -> tuple[MarketHours, np.ndarray]:
    """Derived per-hour inputs and observation template of a table (computed once per table)."""
    cached = _HOURS_CACHE.get(id(table))
    if cached is None or cached[0] is not table:
        hours = MarketHours.from_table(table)
        cached = (table, hours, observation_template(hours))
        _HOURS_CACHE[id(table)] = cached
    return cached[1], cached[2]


def start_hours(
    n_hours: int, episode_steps: int, start_days: list[int] | None = None, source: str = "the dataset"
) -> np.ndarray:
    """Admissible episode starts: midnights with a full episode after them, on ``start_days`` when
    given (day 1 = hour 0; a day without a full episode after it is a ConfigError)."""
    last = max(n_hours - episode_steps, 0)  # a dataset no longer than an episode: one start, hour 0
    starts = np.arange(0, last + 1, 24, dtype=np.int64)
    return select_starts(starts, start_days, 24, source)
