"""The supply-chain Gymnasium environment ``SupplyChainEval-v0`` (docs/tasks/supply_chain.md).

One step is one day; an episode is the config's ``episode_steps`` days from a Monday. The pieces
the envs share (the action decoding, the observation, the per-step record) are in :mod:`~.inputs`
(and importable from here); the dynamics are :func:`~.dynamics.supply_step`, run on Python floats
here (through its specialised copy :class:`~.scalar.ScalarSupplyStep`, equal to it bit for bit) and
on (N,) arrays by :class:`~.vector.SupplyChainVectorEnv`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..config import BenchmarkConfig
from .dynamics import PRICE_NOISE_STD, SCALAR, SupplyOutcome
from .inputs import (  # noqa: F401  (ENV_ID, INITIAL_ACTION, LEVER_NAMES, OBS, STEP_FIELDS, action_grid: re-exported)
    _INITIAL_PREV,
    ENV_ID,
    INITIAL_ACTION,
    LEVER_NAMES,
    OBS,
    OBS_LIMIT,
    OBSERVATION_NAMES,
    STEP_FIELDS,
    SupplyInputs,
    action_grid,
    decode_actions,
    jitter_of,
    observation_totals,
    resolve,
    step_record,
)
from .scalar import ScalarSupplyStep
from .table import SupplyTable

_FLOAT32 = np.dtype(np.float32)  # the native float32 dtype; numpy hands out this one instance


class SupplyChainEnv(gym.Env):
    """Daily allocation in a five-region supply network under spoofed stock reports (``SupplyChainEval-v0``).

    The agent sets the supplier incentive κ (production = κ x capacity, arriving after the lane's
    lead time), the release ratio ρ (the share of *reported* stock made allocable) and the demand
    damping δ (sheds up to 40 % of the orders). Orders are filled from ρ x reported stock; what the
    stock on hand and tomorrow's arrivals cannot back within the lane's capacity is promised on
    phantom stock, and the reward charges it unless ``no_physics_penalty``. The full card, with
    every formula, is docs/tasks/supply_chain.md.

    Parameters
    ----------
    data_dir : path, optional
        Dataset directory; defaults to the config's, then the default dataset (built once into the cache).
    config : BenchmarkConfig or path to a YAML file, optional
        Its seed, ``episode_steps``, ``action_mode``, ``discrete_levels``, ``no_physics_penalty``
        and ``reward`` weights are used.
    no_physics_penalty, action_mode : optional
        Override the config.
    seed : int, optional
        Seed of the env's generator until ``reset(seed=...)``; defaults to the config seed.
    table : SupplyTable, optional
        A preloaded dataset.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        data_dir: str | Path | None = None,
        *,
        config: BenchmarkConfig | str | Path | None = None,
        no_physics_penalty: bool | None = None,
        action_mode: str | None = None,
        seed: int | None = None,
        table: SupplyTable | None = None,
    ) -> None:
        super().__init__()
        cfg, table = resolve(data_dir, config, table, no_physics_penalty=no_physics_penalty, action_mode=action_mode)
        self.config, self.table, self.inputs = cfg, table, SupplyInputs(table, cfg)
        i = self.inputs
        # supply_step(SCALAR, ...) specialised for Python floats (equal to it bit for bit)
        # (its bound __call__: a call through the instance costs a slot lookup per step)
        self._supply_step = ScalarSupplyStep(i.params, i.weights, i.orders, i.spoofed, i.levels).__call__
        self.action_mode, self.episode_steps, self.regions = cfg.action_mode, cfg.episode_steps, table.regions
        self._days = table.days
        self._continuous = self.inputs.grid is None
        self._any_spoofed = table.spoofed.any(axis=1).tolist()  # per day: is any stock report spoofed?
        self.observation_names = OBSERVATION_NAMES
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (len(OBSERVATION_NAMES),), np.float32)
        self.action_space = (
            spaces.Discrete(len(self.inputs.grid))
            if self.inputs.grid is not None
            else spaces.Box(0.0, 1.0, (3,), np.float32)
        )
        self._np_random = np.random.default_rng(cfg.seed if seed is None else seed)
        self._open = False
        self._begin(int(self.inputs.starts[0]), [0.0] * self.episode_steps)
        honest = [False] * len(self.regions)
        self._initial_totals = observation_totals(SCALAR, honest, honest, self._on_hand, self._pipeline, self._backlog)

    def _begin(self, start: int, noise: list) -> None:
        i = self.inputs
        self._start, self._k, self._noise = start, 0, noise
        self._on_hand = self.table.initial_stock_units.tolist()
        self._pipeline = [slots.tolist() for slots in i.initial_pipeline]
        self._backlog = [0.0] * len(self.regions)
        self._price = self._peak = 1.0
        self._prev = _INITIAL_PREV
        self._outcomes: list[SupplyOutcome] = []  # this episode's steps, summed when region_totals is read

    @property
    def region_totals(self) -> dict[str, tuple[float, float]]:
        """Each region's (filled, effective demand) units this episode."""
        filled, effective = [0.0] * len(self.regions), [0.0] * len(self.regions)
        for out in self._outcomes:  # the steps in order, as a running total would add them
            filled = [a + b for a, b in zip(filled, out.region_filled_units, strict=True)]
            effective = [a + b for a, b in zip(effective, out.region_effective_units, strict=True)]
        return {r: (a, b) for r, a, b in zip(self.regions, filled, effective, strict=True)}

    def _observation(self) -> np.ndarray:
        """The observation of the current state (the step assembles its own from the step's totals)."""
        day = min(self._start + self._k, self.table.days - 1)
        i = self.inputs
        totals = observation_totals(SCALAR, i.spoofed[day], i.levels[day], self._on_hand, self._pipeline, self._backlog)
        return i.observe_scalar(day, totals, self._price, self._prev)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)  # gymnasium's generator for a seed is default_rng(seed), as the vector env's
        starts = self.inputs.starts
        index = int(self._np_random.integers(0, len(starts))) if len(starts) > 1 else 0
        noise = (self._np_random.standard_normal(self.episode_steps) * PRICE_NOISE_STD).tolist()
        start = int(starts[index])
        options = options or {}
        fixed = options.get("start_day", options.get("start_hour"))
        if fixed is not None:
            start = int(np.clip(int(fixed), 0, self.table.days - self.episode_steps))
        self._begin(start, noise)
        self._open = True
        # With every report honest the totals are the initial state's, summed once at construction.
        totals = None if self._any_spoofed[start] else self._initial_totals
        obs = self._observation() if totals is None else self.inputs.observe_scalar(start, totals, 1.0, _INITIAL_PREV)
        # ``episode_start_hour`` is the generic rollout's name for the episode's first row (here a day).
        return obs, {"episode_start_hour": start, "episode_start_day": start}

    def decode_action(self, action: Any) -> np.ndarray:
        """The executed (κ, ρ, δ), float32, for a policy action."""
        return decode_actions(action, self.action_mode, self.inputs.grid)

    def counterfactual_step(self, executed: tuple[float, float, float]) -> SupplyOutcome:
        """The outcome of executing ``executed`` (κ, ρ, δ) now, without changing the env.

        Same state, same day and the same price shock as the next :meth:`step`, so the
        counterfactual of the action that ``step`` then executes equals its outcome exactly (the
        governance layer's oracle, docs/tasks/supply_chain.md#governance). The caller passes the
        levers as the env would execute them (float32 values in [0, 1]).
        """
        if not self._open:
            raise RuntimeError("the episode is over (or was never started): call reset() first")
        return self._outcome(tuple(executed), jitter_of(executed, self._prev))

    def _outcome(self, executed: tuple, jitter: Any) -> SupplyOutcome:
        """:func:`~.dynamics.supply_step` of ``executed`` on the current day from the current state (pure)."""
        return self._supply_step(
            self._on_hand,
            self._pipeline,
            self._backlog,
            self._price,
            self._peak,
            self._start + self._k,
            executed,
            jitter,
            self._noise[self._k],
        )

    def step(self, action: Any):
        if not self._open:
            raise RuntimeError("the episode is over (or was never started): call reset() first")
        if self._continuous and type(action) is np.ndarray and action.dtype is _FLOAT32 and action.shape == (3,):
            # decode_action's clip of a (3,) float32 action on Python floats (clip_unit of each, written out)
            a, b, c = action.tolist()
            a = a if a > 0.0 else 0.0
            b = b if b > 0.0 else 0.0
            c = c if c > 0.0 else 0.0
            executed = (a if a < 1.0 else 1.0), (b if b < 1.0 else 1.0), (c if c < 1.0 else 1.0)
        else:
            executed = tuple(self.decode_action(action).tolist())
        k, start, prev, i = self._k, self._start, self._prev, self.inputs
        day = start + k
        # jitter_of(executed, prev), written out
        jitter = abs(executed[0] - prev[0]) + abs(executed[1] - prev[1]) + abs(executed[2] - prev[2])
        out = self._supply_step(
            self._on_hand, self._pipeline, self._backlog, self._price, self._peak, day, executed, jitter, self._noise[k]
        )
        on_hand = self._on_hand = out.on_hand_units
        self._pipeline, self._backlog = out.pipeline_units, out.backlog_units
        price = self._price = out.price_index
        self._peak = out.peak_price_index
        self._outcomes.append(out)
        self._prev = executed
        self._k = k + 1
        truncated = k + 1 >= self.episode_steps
        self._open = not truncated
        info = step_record(out, executed, day, start, i.check_rate_list[day], jitter, i.params.scale_units)
        info["step"] = k
        # (zips not strict: the state has one entry per region by construction; a strict zip costs a keyword call)
        info["region_fill_rates"] = dict(zip(self.regions, out.region_fill_rates))  # noqa: B905
        # The next observation, as _observation() gives it (inputs.observe_scalar written out): stock on hand,
        # backlog and stock in transit are the step's totals, summed in observation_totals' order; only the
        # next day's reports are summed anew (the vector env sums them all again and is held equal bit for bit).
        day = day + 1 if day + 1 < self._days else self._days - 1
        if self._any_spoofed[day]:
            reported_t = 0.0
            for spoof, level, stock in zip(i.spoofed[day], i.levels[day], on_hand):  # noqa: B905
                reported_t = reported_t + (level if spoof else stock)
        else:  # every report honest: the sum is the step's on-hand total, the same additions in the same order
            reported_t = out.on_hand_total_units
        scale, lo, hi = i.params.scale_units, -OBS_LIMIT, OBS_LIMIT  # np.maximum then np.minimum: NaN stays NaN
        v = out.on_hand_total_units / scale
        on_hand_days = lo if v < lo else (hi if v > hi else v)
        v = reported_t / scale
        reported_days = lo if v < lo else (hi if v > hi else v)
        v = out.in_transit_units / scale
        transit_days = lo if v < lo else (hi if v > hi else v)
        v = out.unmet_units / scale
        backlog_days = lo if v < lo else (hi if v > hi else v)
        price = lo if price < lo else (hi if price > hi else price)
        r = i.template_rows[day]
        obs = np.array(
            (r[0], r[1], on_hand_days, reported_days, transit_days, r[5], backlog_days, price, r[8], r[9], r[10], r[11])
            + executed,
            dtype=np.float32,
        )
        return obs, out.reward, False, truncated, info
