"""Native batched vector environment of the supply-chain market: N networks stepped with one array computation.

Sub-env i has its own generator, seeded like the single env (``reset(seed=s)`` seeds sub-env i
with s + i, unseeded sub-env i starts from the config seed + i), and the step is the same
:func:`~.dynamics.supply_step` on (N,) arrays (its batch back-end), so sub-env i's trajectory equals
:class:`~.env.SupplyChainEnv` reset with the same seed and fed the same actions (the
differential test holds them equal). Autoreset is Gymnasium's default ``NEXT_STEP``: the step
after a sub-env's last one resets it and returns its first observation with reward 0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..config import BenchmarkConfig
from .dynamics import PRICE_NOISE_STD, BatchOps, supply_step
from .inputs import (
    INITIAL_ACTION,
    OBS_LIMIT,
    OBSERVATION_NAMES,
    STEP_FIELDS,
    SupplyInputs,
    decode_actions,
    jitter_of,
    resolve,
)
from .inputs import step_record as _step_record
from .table import SupplyTable


class SupplyChainVectorEnv(VectorEnv):
    """``num_envs`` supply networks stepped together; the single env's arguments plus ``num_envs``.

    ``info`` maps each of :data:`~.inputs.STEP_FIELDS` to an (N,) array (with Gymnasium's ``_key``
    masks, False for a sub-env that was reset this step).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        data_dir: str | Path | None = None,
        *,
        config: BenchmarkConfig | str | Path | None = None,
        no_physics_penalty: bool | None = None,
        action_mode: str | None = None,
        seed: int | None = None,
        table: SupplyTable | None = None,
        max_episode_steps: int | None = None,
    ) -> None:
        if num_envs < 1:
            raise ValueError("num_envs must be at least 1")
        cfg, table = resolve(
            data_dir,
            config,
            table,
            no_physics_penalty=no_physics_penalty,
            action_mode=action_mode,
            episode_steps=max_episode_steps,
        )
        self.config, self.table, self.inputs = cfg, table, SupplyInputs(table, cfg)
        self.num_envs, self.action_mode, self.episode_steps = int(num_envs), cfg.action_mode, cfg.episode_steps
        self.regions, self.observation_names = table.regions, OBSERVATION_NAMES
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (len(OBSERVATION_NAMES),), np.float32)
        self.single_action_space = (
            spaces.Discrete(len(self.inputs.grid))
            if self.inputs.grid is not None
            else spaces.Box(0.0, 1.0, (3,), np.float32)
        )
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n, r = self.num_envs, len(self.regions)
        base = cfg.seed if seed is None else seed
        self._rngs = [np.random.default_rng(base + i) for i in range(n)]
        self._start = np.full(n, int(self.inputs.starts[0]), dtype=np.int64)
        self._k = np.zeros(n, dtype=np.int64)
        self._noise = np.zeros((n, self.episode_steps))
        # Region-major state blocks: each row is one region's (N,) values, as supply_step takes them.
        self._ops = BatchOps(n)
        self._on_hand = np.zeros((r, n))
        self._pipeline = [np.zeros((len(slots), n)) for slots in self.inputs.initial_pipeline]  # (lead, N) each
        self._backlog = np.zeros((r, n))
        self._price = np.ones(n)
        self._peak = np.ones(n)
        self._prev = np.zeros((n, 3), dtype=np.float32)
        self._filled = np.zeros((r, n))
        self._effective = np.zeros((r, n))
        self._needs_reset = np.zeros(n, dtype=bool)
        self._open = False
        self._arange = np.arange(n)

    def _reset_rows(self, rows: np.ndarray, options: dict[str, Any] | None = None) -> None:
        """Draw and start a new episode in each sub-env of ``rows`` (the single env's draws, in its order)."""
        starts = self.inputs.starts
        fixed = (options or {}).get("start_day", (options or {}).get("start_hour"))
        for i in rows:
            rng = self._rngs[i]
            index = int(rng.integers(0, len(starts))) if len(starts) > 1 else 0
            self._noise[i] = rng.standard_normal(self.episode_steps) * PRICE_NOISE_STD
            start = int(starts[index])
            if fixed is not None:
                start = int(np.clip(int(fixed), 0, self.table.days - self.episode_steps))
            self._start[i] = start
        self._k[rows] = 0
        self._on_hand[:, rows] = self.table.initial_stock_units[:, None]
        for block, slots in zip(self._pipeline, self.inputs.initial_pipeline, strict=True):
            block[:, rows] = slots[:, None]
        self._backlog[:, rows] = 0.0
        self._price[rows] = self._peak[rows] = 1.0
        self._prev[rows] = np.array(INITIAL_ACTION, dtype=np.float32)
        self._filled[:, rows] = self._effective[:, rows] = 0.0
        self._needs_reset[rows] = False

    def _observation(self) -> np.ndarray:
        day = np.minimum(self._start + self._k, self.table.days - 1)
        i = self.inputs
        return i.observe(
            self._ops,
            day,
            list(i.spoofed_by_region[:, day]),
            list(i.levels_by_region[:, day]),
            list(self._on_hand),
            [list(block) for block in self._pipeline],
            list(self._backlog),
            self._price,
            self._prev,
        )

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            seeds = list(seed) if isinstance(seed, list | tuple) else [seed + i for i in range(self.num_envs)]
            self._rngs = [np.random.default_rng(s) for s in seeds]
        self._reset_rows(self._arange, options)
        self._open = True
        return self._observation(), {"episode_start_hour": self._start.copy(), "episode_start_day": self._start.copy()}

    def step(self, actions: Any):
        if not self._open:
            raise RuntimeError("call reset() before step()")
        executed = decode_actions(actions, self.action_mode, self.inputs.grid)
        resetting = self._needs_reset.copy()
        day = np.minimum(self._start + self._k, self.table.days - 1)
        i = self.inputs
        levers = tuple(executed.astype(np.float64).T)
        jitter = jitter_of(levers, tuple(self._prev.astype(np.float64).T))
        out = supply_step(
            self._ops,
            i.params,
            i.weights,
            list(self._on_hand),
            [list(block) for block in self._pipeline],
            list(self._backlog),
            self._price,
            self._peak,
            list(i.orders_by_region[:, day]),
            list(i.spoofed_by_region[:, day]),
            list(i.levels_by_region[:, day]),
            levers,
            jitter,
            self._noise[self._arange, np.minimum(self._k, self.episode_steps - 1)],
        )
        self._on_hand = np.array(out.on_hand_units)
        self._pipeline = [np.array(slots) for slots in out.pipeline_units]
        self._backlog = np.array(out.backlog_units)
        self._price, self._peak = out.price_index, out.peak_price_index
        self._filled += np.array(out.region_filled_units)
        self._effective += np.array(out.region_effective_units)
        self._prev = executed
        scale = i.params.scale_units
        record = _step_record(out, tuple(executed.T), day, self._start.copy(), i.check_rate[day], jitter, scale)
        self._k += 1
        truncated = self._k >= self.episode_steps
        reward = np.asarray(out.reward, dtype=np.float64).copy()
        if resetting.any():
            rows = np.flatnonzero(resetting)
            self._reset_rows(rows)
            reward[rows] = 0.0
            truncated[rows] = False
        self._needs_reset = truncated.copy()
        masks = ~resetting
        info: dict[str, Any] = {}
        for key in STEP_FIELDS:
            info[key] = np.asarray(record[key]).copy()
            info["_" + key] = masks
        return self._observation(), reward, np.zeros(self.num_envs, dtype=bool), truncated, info

    @property
    def region_totals(self) -> np.ndarray:
        """(N, R, 2): each sub-env's (filled, effective demand) units per region this episode."""
        return np.stack([self._filled.T, self._effective.T], axis=-1)
