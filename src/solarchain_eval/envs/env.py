"""The SolarChain-Eval Gymnasium environment (docs/environment.md): one episode = 24 hourly decisions."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ..config import BenchmarkConfig
from ..data.table import HourlyTable
from ..market.actions import action_jitter_f32
from ..market.dynamics import StepOutcome, market_step
from ..market.observation import OBS_LIMIT, OBS_LIQUIDITY, OBS_PREV_ALPHA, OBS_PREV_ELL, OBS_PRICE
from ..market.ops import SCALAR

# The set-up every back-end shares and the step's info live in market_setup and step_info; the
# `x as x` imports keep their names importable from here.
from .market_setup import env_config as env_config
from .market_setup import market_inputs as market_inputs
from .market_setup import resolve_config as resolve_config
from .market_setup import resolve_table as resolve_table
from .market_setup import setup_market
from .market_setup import start_hours as start_hours
from .rng_stream import PRICE_NOISE_STD, EpisodeStream
from .step_info import STEP_INFO_KEYS as STEP_INFO_KEYS
from .step_info import step_info

ActionMode = str  # "continuous" | "discrete"


class SolarChainEnv(gym.Env):
    """Hourly governance of a decentralised solar-energy market (``SolarChainEval-v0``).

    The full card, with every formula, is docs/environment.md.

    Description
    -----------
    Each hour the agent sets the reward ratio α, the liquidity ratio ℓ and the burn rate b of
    a P2P solar market of five cities. Supply comes from PV reports, some of them physically
    impossible or false-data injected; the more the agent allocates (α + ℓ), the more of that
    invalid supply it backs, and the reward charges it. Energies are MWh per hour.

    Action Space
    ------------
    ``Box(0, 1, (3,), float32)``: NaN → 0, ±inf → 1/0, clip to [0, 1], then in float32
    α = 0.05 + 0.60 u1 ∈ [0.05, 0.65], ℓ = 0.20 + 0.75 u2 ∈ [0.20, 0.95], b = 0.20 u3 ∈ [0, 0.20];
    sanitised: each clipped to its range, and both α, ℓ scaled by 0.98 / (α + ℓ) when
    α + ℓ > 0.98. ``action_mode="discrete"``: ``Discrete(125)``, the grid {0, .25, .5, .75, 1}^3
    in ``itertools.product`` order, decoded the same way.

    Observation Space
    -----------------
    ``Box(-10, 10, (12,), float32)``, each feature clipped to [-10, 10]: sin and cos of the
    hour of day; verified G_v, reported G_r and physical-maximum P_max supply (MWh); supply gap
    (G_v - Q) / max(Q, 1e-6) with the trade demand Q; liquidity L (MWh); token price p; raw
    violation rate ν; static slippage σ; previous α; previous ℓ (``observation_names``).

    Rewards
    -------
    R = M - λd D - λj J - λu U - λf F - λp (V + A): matched volume M, liquidity drawdown D,
    action jitter J = |a - a_prev|_1, unmet demand U, fairness variance F, physics violation
    rate V and unsafe backed supply A. Defaults λd 1.50, λj 0.25, λu 0.40, λf 0.20, λp 2.00.
    The no-physics ablation drops λp (V + A) and still records V and A.

    Starting State
    --------------
    A start midnight drawn from {0, 24, ..., hours - 24} (or ``options["start_hour"]``);
    L = 1 MWh, p = 1, previous action float32(0.25, 0.75, 0.02).

    Episode End
    -----------
    Truncated after ``episode_steps`` (24) steps; never terminated.

    Arguments
    ---------
    See Parameters below; the config supplies the ranges, λ weights and seed.

    Vectorized environment
    ----------------------
    ``gym.make_vec(..., vectorization_mode="vector_entry_point")``: a native batched env;
    sub-env i equals this env reset with seed s + i.

    Info
    ----
    Every per-step quantity under the original release's names (``STEP_INFO_KEYS``, units
    in docs/environment.md#info), plus ``step`` and ``city_rewards``; ``cost`` = V + A for
    safe-RL algorithms.

    Version History
    ---------------
    v0: first release, bit-for-bit with the original release's per-step records.

    Parameters
    ----------
    data_dir : path, optional
        Dataset directory (four CSVs). Defaults to the config's ``data_dir``, then the
        embedded default dataset (built once into the user cache).
    config : BenchmarkConfig or path to a YAML file, optional
        Configuration; defaults to ``BenchmarkConfig()``.
    no_physics_penalty : bool, optional
        Drop λp (V + A) from the reward (V and A are still recorded). Overrides the config.
    action_mode : {"continuous", "discrete"}, optional
        ``Box(0, 1, (3,))`` or ``Discrete(levels**3)``. Overrides the config.
    seed : int, optional
        Seed of the env's generator until ``reset(seed=...)``; defaults to the config seed.
    table : HourlyTable, optional
        A preloaded hourly table (skips loading ``data_dir``).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        data_dir: str | Path | None = None,
        *,
        config: BenchmarkConfig | str | Path | None = None,
        no_physics_penalty: bool | None = None,
        action_mode: ActionMode | None = None,
        seed: int | None = None,
        table: HourlyTable | None = None,
    ) -> None:
        super().__init__()
        setup_market(
            self, data_dir, config, no_physics_penalty=no_physics_penalty, action_mode=action_mode, table=table
        )
        cfg = self.config
        self.observation_space = self.single_observation_space
        self.action_space = self.single_action_space

        # Per-hour inputs as Python lists: list indexing of floats is the cheapest lookup.
        hours, t = self.market_hours, self.table
        self._verified = t.verified_mwh.tolist()
        self._reported = t.reported_mwh.tolist()
        self._unsafe = hours.unsafe_supply_mwh.tolist()
        self._demand = hours.clearing_demand_mwh.tolist()
        self._raw_rate = t.raw_violation_rate.tolist()
        self._share = [tuple(row) for row in hours.city_share.tolist()]
        self._trust = [tuple(row) for row in hours.city_trust.tolist()]
        m = cfg.market
        self._initial_liquidity = m.initial_liquidity
        self._initial_price = m.initial_token_price

        self._np_random = np.random.default_rng(cfg.seed if seed is None else seed)
        self._stream = EpisodeStream(self._np_random)
        self._noise_buffer = np.empty(self.episode_steps)
        self._episode_open = False
        self._set_episode(0, [0.0] * self.episode_steps)

    # --- episode bookkeeping ------------------------------------------------------------------
    def _set_episode(self, start: int, noise: list) -> None:
        self._start = start
        self._k = 0
        self._noise = noise
        self._liquidity = self._peak_liquidity = self._initial_liquidity
        self._price = self._peak_price = self._initial_price
        self._prev = self._initial_action
        self._city_totals = [0.0] * len(self.cities)

    def _observation(self, hour: int) -> np.ndarray:
        obs = self._obs_template[hour].copy()
        liquidity, price = self._liquidity, self._price
        obs[OBS_LIQUIDITY] = liquidity if liquidity < OBS_LIMIT else OBS_LIMIT
        obs[OBS_PRICE] = price if price < OBS_LIMIT else OBS_LIMIT
        obs[OBS_PREV_ALPHA] = self._prev[0]
        obs[OBS_PREV_ELL] = self._prev[1]
        return obs

    @property
    def episode_start_hour(self) -> int:
        return self._start

    @property
    def city_totals(self) -> dict[str, float]:
        """Each city's accumulated reward tokens this episode."""
        return dict(zip(self.cities, self._city_totals, strict=True))

    # --- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is None and self._episode_open:
            self._stream.truncate_last(self._k)  # an episode cut short drew fewer shocks
        super().reset(seed=seed)
        if self._stream.rng is not self._np_random:  # reseeded (here or by the user)
            self._stream = EpisodeStream(self._np_random)
        fixed_start = options is not None and "start_hour" in options
        draw_start = not fixed_start and self._n_hours > self.episode_steps
        index = self._stream.begin(len(self._starts) if draw_start else 0, self._noise_buffer)
        if fixed_start:
            start = int(np.clip(int(options["start_hour"]), 0, max(self._n_hours - self.episode_steps, 0)))
        else:
            start = int(self._starts[index]) if draw_start else 0
        self._set_episode(start, (self._noise_buffer * PRICE_NOISE_STD).tolist())
        self._episode_open = True
        return self._observation(start), {"episode_start_hour": start, "absolute_hour": start}

    def decode_action(self, action: Any) -> tuple[float, float, float]:
        """The executed (α, ℓ, b) for a policy action (float32 values)."""
        if self.action_mode == "discrete":
            return self._discrete_actions.decode(action)
        return self.codec.decode(action)

    def counterfactual_step(self, executed: tuple[float, float, float]) -> StepOutcome:
        """The outcome of executing ``executed`` (market units) now, without changing the env.

        Same state, same hour and the same price shock as the next :meth:`step`, so the
        counterfactual of the action that ``step`` then executes equals its outcome exactly
        (docs/governance.md#counterfactual-step-records). The caller passes the action as the
        env would execute it (float32 values, sanitised).
        """
        if not self._episode_open or self._k >= self.episode_steps:
            raise RuntimeError("the episode is over (or was never started): call reset() first")
        return self._outcome(executed, self._hour())

    def _hour(self) -> int:
        """The hourly-table row of the current step (the last row once an episode runs past the data)."""
        hour = self._start + self._k
        return hour if hour < self._n_hours else self._n_hours - 1

    def _outcome(self, executed: tuple[float, float, float], hour: int) -> StepOutcome:
        """``market_step`` of ``executed`` at ``hour`` from the current state and price shock (pure)."""
        return market_step(
            SCALAR,
            self.weights,
            self._verified[hour],
            self._unsafe[hour],
            self._demand[hour],
            self._share[hour],
            self._trust[hour],
            self._liquidity,
            self._peak_liquidity,
            self._price,
            self._peak_price,
            executed,
            action_jitter_f32(executed, self._prev),
            self._noise[self._k],
        )

    def step(self, action: Any):
        k = self._k
        if not self._episode_open or k >= self.episode_steps:
            raise RuntimeError("the episode is over (or was never started): call reset() first")
        executed = self.decode_action(action)
        hour = self._hour()
        out = self._outcome(executed, hour)
        self._liquidity, self._peak_liquidity = out.liquidity, out.peak_liquidity
        self._price, self._peak_price = out.token_price, out.peak_price
        self._prev = executed
        totals = self._city_totals
        for i, value in enumerate(out.city_rewards):
            totals[i] += value
        k += 1
        self._k = k
        truncated = k >= self.episode_steps
        if truncated:
            self._episode_open = False
        next_hour = self._start + k
        obs = self._observation(next_hour if next_hour < self._n_hours else self._n_hours - 1)
        info = step_info(
            out,
            executed,
            hour,
            self._start,
            (self._verified[hour], self._reported[hour], self._unsafe[hour], self._raw_rate[hour], self._demand[hour]),
            self._depth_scale,
        )
        info["step"] = k - 1
        info["city_rewards"] = dict(zip(self.cities, out.city_rewards, strict=True))
        return obs, out.reward, False, truncated, info
