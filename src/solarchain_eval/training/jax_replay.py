"""The replay buffer of the JAX backend's SAC and DQN: rejax's, sampled as SB3 samples.

rejax draws a minibatch *without* replacement through ``jax.random.choice(..., p=...)`` over
the whole buffer, which builds arrays of the buffer's size at every update: O(buffer) work per
step, negligible for a 2,000-step benchmark and half of SAC's step time at the paper's 300,000
(a buffer that large costs milliseconds per update to sample from). SB3's ``ReplayBuffer``
draws ``batch_size`` indices uniformly *with* replacement among the stored transitions
(``np.random.randint(0, upper_bound, size=batch_size)``, ``upper_bound`` the buffer size once
full, else the next write position); so does :class:`SB3ReplayBuffer`, in O(batch) work.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from rejax.buffers import Minibatch, ReplayBuffer


class SB3ReplayBuffer(ReplayBuffer):
    """rejax's circular :class:`~rejax.buffers.ReplayBuffer` with SB3's minibatch sampling."""

    def sample(self, num: int, rng: jax.Array) -> Minibatch:
        """``num`` transitions drawn uniformly with replacement from those stored.

        With nothing stored yet the draw is from index 0 (rejax's training never samples
        before ``fill_buffer`` transitions are in).
        """
        index = jax.random.randint(rng, (num,), 0, jnp.maximum(self.num_entries, 1))
        return jax.tree.map(lambda column: column[index], self.data)
