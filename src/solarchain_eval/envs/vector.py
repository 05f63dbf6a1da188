"""Native batched vector environment: N sub-environments stepped with one array computation.

Every sub-env has its own random generator, seeded like the single env (``reset(seed=s)``
seeds sub-env i with s + i), and the step is the same :func:`market_step` evaluated on
arrays, so sub-env i's trajectory equals ``SolarChainEnv`` reset with the same seed and fed
the same actions, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..config import BenchmarkConfig
from ..data.table import HourlyTable
from ..market.actions import action_jitter_f32_batch
from ..market.dynamics import market_step
from ..market.observation import OBS_LIMIT, OBS_LIQUIDITY, OBS_PREV_ALPHA, OBS_PREV_ELL, OBS_PRICE
from ..market.ops import BATCH
from .market_setup import setup_market
from .rng_stream import CHECKPOINT_EVERY, PRICE_NOISE_STD, EpisodeStream
from .step_info import STEP_INFO_KEYS, step_info

#: The market state carried between steps: market_step's state arguments in their order and
#: the StepOutcome fields that update them. The vector env keeps it as one (4, N) array.
_STATE_FIELDS = ("liquidity", "peak_liquidity", "token_price", "peak_price")
_LIQUIDITY, _PRICE = _STATE_FIELDS.index("liquidity"), _STATE_FIELDS.index("token_price")


class SolarChainVectorEnv(VectorEnv):
    """``num_envs`` SolarChain markets stepped together.

    Accepts the single env's keyword arguments plus ``autoreset_mode``
    (``NEXT_STEP``, Gymnasium's default, or ``SAME_STEP``). ``info`` maps each per-step
    quantity to an array over sub-envs (with Gymnasium's ``_key`` masks) and
    ``city_rewards`` to an (N, C) array. Unseeded sub-env i starts from config seed + i.
    """

    def __init__(
        self,
        num_envs: int = 1,
        data_dir: str | Path | None = None,
        *,
        config: BenchmarkConfig | str | Path | None = None,
        no_physics_penalty: bool | None = None,
        action_mode: str | None = None,
        seed: int | None = None,
        table: HourlyTable | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
    ) -> None:
        if num_envs < 1:
            raise ValueError("num_envs must be at least 1")
        mode = AutoresetMode(autoreset_mode)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError("autoreset_mode must be NEXT_STEP or SAME_STEP")
        self.metadata = {"autoreset_mode": mode, "render_modes": []}
        self.num_envs = int(num_envs)
        setup_market(
            self,
            data_dir,
            config,
            no_physics_penalty=no_physics_penalty,
            action_mode=action_mode,
            table=table,
            episode_steps=max_episode_steps,
        )
        cfg = self.config
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        hours, t = self.market_hours, self.table
        self._plain_starts = len(self._starts) if t.hours > self.episode_steps else 0
        # One gather per step: the hour's scalar inputs side by side, and the city columns.
        self._hour_inputs = np.ascontiguousarray(  # (5, H): gathers give contiguous (5, N) rows
            np.vstack(
                [
                    t.verified_mwh,
                    hours.unsafe_supply_mwh,
                    hours.clearing_demand_mwh,
                    t.reported_mwh,
                    t.raw_violation_rate,
                ]
            )
        )
        # (2C, H): one gather gives the (C, N) share and trust arrays with contiguous rows.
        self._n_cities = len(self.cities)
        self._city_inputs = np.ascontiguousarray(np.vstack([hours.city_share.T, hours.city_trust.T]))
        m = cfg.market
        self._initial_prev = np.array(self._initial_action, dtype=np.float32)[:, None]  # a (3, 1) column

        n = self.num_envs
        base = cfg.seed if seed is None else seed
        self._streams = [EpisodeStream(np.random.default_rng(base + i)) for i in range(n)]
        self._draw_int = [stream.rng.integers for stream in self._streams]
        self._draw_normal = [stream.rng.standard_normal for stream in self._streams]
        # Autoreset episodes drawn but not yet written to their stream's log (see _reset_many).
        self._pending = np.zeros(n, dtype=np.int64)
        self._since_checkpoint = np.zeros(n, dtype=np.int64)
        self._noise = np.zeros((n, self.episode_steps))
        self._noise_rows = list(self._noise)  # row views, filled in place by the streams
        self._arange = np.arange(n)
        self._start = np.zeros(n, dtype=np.int64)
        self._k = np.zeros(n, dtype=np.int64)
        self._open = np.zeros(n, dtype=bool)
        self._needs_reset = np.zeros(n, dtype=bool)
        # One array for the state (see _STATE_FIELDS), so commits and resets cannot miss a field.
        self._initial_state = np.array(
            [m.initial_liquidity, m.initial_liquidity, m.initial_token_price, m.initial_token_price]
        )[:, None]
        self._state = np.repeat(self._initial_state, n, axis=1)
        self._prev = np.zeros((3, n), dtype=np.float32)  # component-major
        self._lockstep: int | None = None  # the common step index when all sub-envs share it
        self._all_true = np.ones(n, dtype=bool)
        self._all_true.setflags(write=False)  # shared by every info mask; read-only
        self._info_masks = {"_" + key: self._all_true for key in (*STEP_INFO_KEYS, "city_rewards")}

    # --- resets -------------------------------------------------------------------------------
    def _flush(self, i: int) -> EpisodeStream:
        """Write sub-env i's pending autoreset episodes into its stream's log."""
        stream = self._streams[i]
        if self._pending[i]:
            stream.record(self._plain_starts, self.episode_steps, int(self._pending[i]))
            self._pending[i] = 0
        return stream

    def _reset_many(
        self,
        mask: np.ndarray,
        seeds: Sequence[int | None] | None = None,
        start_hours: Sequence[int | None] | None = None,
    ) -> None:
        """Reset the sub-envs in ``mask``; ``seeds``/``start_hours`` None means none for any.

        Every sub-env's generator sees exactly the single env's draws (see
        :class:`EpisodeStream`). The draws themselves are batched, and episodes that draw a
        start among all admissible ones are logged in bulk (``_pending``): per-sub-env stream
        calls would cost the benchmark about a third of its throughput.
        """
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return
        indices = idx.tolist()
        seeded = [i for i in indices if seeds[i] is not None] if seeds is not None else []
        fixed = [i for i in indices if start_hours[i] is not None] if start_hours is not None else []
        # Streams that need more than the next episode's draws: a new seed, an episode cut short.
        for i in sorted({*seeded, *fixed, *idx[self._open[idx]].tolist()}):
            stream = self._flush(i)
            if seeds is not None and seeds[i] is not None:
                stream = self._streams[i] = EpisodeStream(np.random.default_rng(seeds[i]))
                self._draw_int[i], self._draw_normal[i] = stream.rng.integers, stream.rng.standard_normal
                self._since_checkpoint[i] = 0
            elif self._open[i]:
                stream.truncate_last(int(self._k[i]))
        for i in idx[self._since_checkpoint[idx] >= CHECKPOINT_EVERY].tolist():
            self._flush(i).checkpoint()
            self._since_checkpoint[i] = 0
        starts = self._start.copy()  # a fresh array: the previous step's info references the old one
        drawing = np.setdiff1d(idx, fixed, assume_unique=True) if fixed else idx
        if self._plain_starts:
            ints, int32 = self._draw_int, np.int32
            starts[drawing] = self._starts[[int(ints[i](0, self._plain_starts, dtype=int32)) for i in drawing.tolist()]]
        else:
            starts[drawing] = 0
        normals, rows = self._draw_normal, self._noise_rows
        for i in indices:
            normals[i](out=rows[i])
        max_start = max(self._n_hours - self.episode_steps, 0)
        for i in fixed:  # no start drawn; its stream was flushed above, so the log stays in order
            starts[i] = min(max(int(start_hours[i]), 0), max_start)
            self._streams[i].record(0, self.episode_steps)
        self._pending[drawing] += 1
        self._since_checkpoint[idx] += 1
        self._noise[idx] *= PRICE_NOISE_STD
        self._start = starts
        self._k = np.where(mask, 0, self._k)
        self._open = self._open | mask
        self._needs_reset = self._needs_reset & ~mask
        self._state = np.where(mask, self._initial_state, self._state)
        self._prev = np.where(mask, self._initial_prev, self._prev)
        # Lockstep: every sub-env at the first step of an open episode (scalar indexing applies).
        lockstep = bool(self._open.all() and not self._k.any() and not self._needs_reset.any())
        self._lockstep = 0 if lockstep else None

    def _observations(self) -> np.ndarray:
        hour = np.minimum(self._start + self._k, self._n_hours - 1)
        obs = np.take(self._obs_template, hour, axis=0)
        obs[:, OBS_LIQUIDITY] = np.minimum(self._state[_LIQUIDITY], OBS_LIMIT)
        obs[:, OBS_PRICE] = np.minimum(self._state[_PRICE], OBS_LIMIT)
        obs[:, OBS_PREV_ALPHA] = self._prev[0]
        obs[:, OBS_PREV_ELL] = self._prev[1]
        return obs

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None):
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"got {len(seeds)} seeds for {n} sub-environments")
        options = options or {}
        mask = np.asarray(options.get("reset_mask", self._all_true), dtype=bool)
        if mask.shape != (n,):
            raise ValueError(f"reset_mask must have shape ({n},)")
        start = options.get("start_hour")
        starts = None if start is None else list(np.broadcast_to(np.asarray(start), (n,)).tolist())
        self._reset_many(mask, None if seed is None else seeds, starts)
        info = {"episode_start_hour": self._start.copy(), "_episode_start_hour": mask.copy()}
        return self._observations(), info

    # --- stepping -----------------------------------------------------------------------------
    def _decode(self, actions: Any) -> np.ndarray:
        if self._discrete_actions is not None:
            return self._discrete_actions.decode_batch(actions, self.num_envs)
        batch = np.asarray(actions)
        if batch.shape != (self.num_envs, 3):
            raise ValueError(f"expected actions of shape ({self.num_envs}, 3), got {batch.shape}")
        return self.codec.decode_batch(batch)

    def step(self, actions: Any):
        n = self.num_envs
        resetting = self._needs_reset  # NEXT_STEP: sub-envs whose episode ended on the last call
        if resetting.all():  # this call only resets, every sub-env
            self._reset_many(resetting)
            zeros, falses = np.zeros(n), np.zeros(n, dtype=bool)
            return self._observations(), zeros, falses, falses.copy(), {}
        k = self._lockstep
        if k is not None:  # the usual case: every sub-env at step k, scalar indexing
            stepping, noise = self._all_true, self._noise[:, k]
            hour = self._start + k
        else:
            if not (self._open | resetting).all():
                raise RuntimeError("a sub-environment's episode is over (or never started): call reset() first")
            stepping = self._all_true if not resetting.any() else ~resetting
            k = np.minimum(self._k, self.episode_steps - 1)  # sub-envs that reset this call read any valid step
            hour = self._start + k
            noise = self._noise[self._arange, k]
        if self._n_hours <= self.episode_steps:  # an episode longer than the table repeats its last hour
            hour = np.minimum(hour, self._n_hours - 1)
        executed32, out, executed, inputs = self._advance(actions, hour, noise)
        self._commit(stepping, executed32, out)
        truncated = stepping & (self._k >= self.episode_steps)
        reward = out.reward if stepping is self._all_true else np.where(stepping, out.reward, 0.0)
        info = self._step_info(out, executed, hour, inputs, stepping)
        self._open = self._open & ~truncated
        if stepping is not self._all_true:
            self._reset_many(resetting)
        obs = self._observations()
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            self._needs_reset = truncated
        elif truncated.any():
            info["final_obs"] = obs
            info["_final_obs"] = truncated.copy()
            self._reset_many(truncated)
            obs = self._observations()
        return obs, reward, np.zeros(n, dtype=bool), truncated, info

    def _advance(self, actions: Any, hour: np.ndarray, noise: np.ndarray):
        executed32 = self._decode(actions)
        executed64 = executed32.astype(np.float64)
        executed = (executed64[0], executed64[1], executed64[2])
        inputs = np.take(self._hour_inputs, hour, axis=1)  # contiguous (5, N) rows
        cities = np.take(self._city_inputs, hour, axis=1)
        out = market_step(
            BATCH,
            self.weights,
            inputs[0],
            inputs[1],
            inputs[2],
            cities[: self._n_cities],
            cities[self._n_cities :],
            *self._state,
            executed,
            action_jitter_f32_batch(executed32, self._prev),
            noise,
        )
        return executed32, out, executed, inputs

    def _commit(self, stepping: np.ndarray, executed32: np.ndarray, out: Any) -> None:
        """Take the step's state for the sub-envs in ``stepping``; the others keep theirs."""
        state = np.stack([getattr(out, field) for field in _STATE_FIELDS])
        if stepping is not self._all_true:
            state = np.where(stepping, state, self._state)
            executed32 = np.where(stepping, executed32, self._prev)
        self._state, self._prev = state, executed32
        self._k = self._k + stepping
        if self._lockstep is not None:
            self._lockstep = self._lockstep + 1 if self._lockstep + 1 < self.episode_steps else None

    def _step_info(self, out: Any, executed: tuple, hour: np.ndarray, inputs: np.ndarray, mask: np.ndarray) -> dict:
        values = step_info(
            out, executed, hour, self._start, (inputs[0], inputs[3], inputs[1], inputs[4], inputs[2]), self._depth_scale
        )
        values["city_rewards"] = out.city_rewards.T
        if mask is self._all_true:
            values.update(self._info_masks)
        else:
            values.update({"_" + key: mask for key in list(values)})
        return values
