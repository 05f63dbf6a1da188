"""The returns of the training episodes, carried in the JAX backend's train state.

rejax keeps no record of the episodes it trains on; :class:`EpisodeReturns` (the train state's
``episode_returns``, added by :func:`~.jax_alignment.sb3_variant`) sums each environment's
rewards and keeps the returns of its last :data:`~.jax_progress.RECENT_EPISODES` finished
episodes, which the trainer reports between chunks as the "recent return". It only reads the
rewards: the training itself is unchanged.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from .jax_progress import RECENT_EPISODES


class EpisodeReturns(struct.PyTreeNode):
    """Per environment: the current episode's return so far, a ring of the last finished
    episodes' returns and how many episodes finished."""

    running: jax.Array  # (num_envs,)
    recent: jax.Array  # (num_envs, RECENT_EPISODES)
    finished: jax.Array  # (num_envs,) int32

    @classmethod
    def empty(cls, num_envs: int) -> EpisodeReturns:
        return cls(
            running=jnp.zeros(num_envs),
            recent=jnp.zeros((num_envs, RECENT_EPISODES)),
            finished=jnp.zeros(num_envs, jnp.int32),
        )

    def record(self, reward: jax.Array, done: jax.Array) -> EpisodeReturns:
        """Add one step's rewards (the env's own, before any bootstrap); ``done`` ends an episode."""
        total = self.running + reward.astype(self.running.dtype)
        slot = jax.nn.one_hot(self.finished % RECENT_EPISODES, RECENT_EPISODES, dtype=bool) & done[:, None]
        return self.replace(
            running=jnp.where(done, 0.0, total).astype(self.running.dtype),
            recent=jnp.where(slot, total[:, None], self.recent),
            finished=self.finished + done.astype(jnp.int32),
        )
