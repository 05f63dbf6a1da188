"""Where the JAX backend changes rejax to follow Stable-Baselines3 (docs/jax.md lists the rest).

rejax has no setting for these, so :func:`sb3_variant` subclasses its algorithm: SB3's
optimiser for all three algorithms, and SB3's value loss and initialisation for PPO.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import jax
import numpy as np

#: Adam's epsilon in SB3: PPO's policies use 1e-5, SAC and DQN torch's default 1e-8.
ADAM_EPS = {"ppo": 1e-5, "sac": 1e-8, "dqn": 1e-8}

#: Where this backend changes rejax to follow SB3 (recorded in each model's identity).
SB3_ALIGNMENT = {
    "ppo": {
        "gradient_clip": "global norm",
        "adam_eps": 1e-5,
        "value_loss": "unclipped, vf_coef * mean squared error",
        "init": "orthogonal: hidden gain sqrt(2), action mean 0.01, value 1; zero biases",
    },
    "sac": {"gradient_clip": "global norm", "adam_eps": 1e-8},
    "dqn": {"gradient_clip": "global norm", "adam_eps": 1e-8},
}


@cache
def sb3_variant(algo: str) -> type:
    """rejax's algorithm class changed where SB3 differs and rejax has no setting for it.

    - The optimiser: rejax chains ``optax.clip(max_grad_norm)`` (each gradient element clipped
      to ±max_grad_norm) with Adam (ε 1e-8); SB3 clips the gradients' global norm and uses
      ε 1e-5 for PPO. Each train state's optimiser is rebuilt after rejax initialises the parameters.
    - PPO's value loss: rejax clips the value prediction to ±clip_eps around the rollout's value
      and halves the squared error; SB3 (``clip_range_vf=None``) uses ``vf_coef * mean((V - R)²)``.
      With returns near -20 and values starting at 0, the clipped loss lets the value move only
      0.2 per rollout.
    - PPO's initialisation: SB3's ``ortho_init`` (:func:`_orthogonal_ppo`) instead of flax's
      LeCun-normal kernels.
    """
    import jax.numpy as jnp
    import optax
    import rejax
    from flax.training.train_state import TrainState
    from rejax.algos.algorithm import register_init

    base = rejax.get_algo(algo)

    class SB3Variant(base):  # type: ignore[misc, valid-type]
        @register_init
        def initialize_network_params(self, rng):
            state = super().initialize_network_params(rng)
            if algo == "ppo":
                state = _orthogonal_ppo(state, rng)
            tx = optax.chain(
                optax.clip_by_global_norm(self.max_grad_norm),
                optax.adam(learning_rate=self.learning_rate, eps=ADAM_EPS[algo]),
            )
            return {
                k: TrainState.create(apply_fn=(), params=v.params, tx=tx) if isinstance(v, TrainState) else v
                for k, v in state.items()
            }

        if algo == "ppo":

            def update_critic(self, ts, batch):
                def critic_loss_fn(params):
                    value = self.critic.apply(params, batch.trajectories.obs)
                    return self.vf_coef * jnp.mean(jnp.square(value - batch.targets))

                grads = jax.grad(critic_loss_fn)(ts.critic_ts.params)
                return ts.replace(critic_ts=ts.critic_ts.apply_gradients(grads=grads))

    SB3Variant.__name__ = f"{base.__name__}SB3Variant"
    return SB3Variant


def _orthogonal_ppo(state: dict[str, Any], rng: jax.Array) -> dict[str, Any]:
    """SB3's PPO initialisation (``ortho_init``): orthogonal kernels with gain √2 in the hidden
    layers, 0.01 for the action mean and 1 for the value; zero biases; the log-std keeps 0."""
    import jax.numpy as jnp

    def reinit(params: Any, output_gain: float, output_layer: str, key: jax.Array) -> Any:
        flat = jax.tree_util.tree_flatten_with_path(params)[0]
        keys = iter(jax.random.split(key, len(flat)))
        leaves = []
        for path, leaf in flat:
            names = [str(getattr(p, "key", p)) for p in path]
            if names[-1] == "kernel":
                gain = output_gain if output_layer in names else np.sqrt(2.0)
                leaf = jax.nn.initializers.orthogonal(scale=gain)(next(keys), leaf.shape, leaf.dtype)
            elif names[-1] == "bias":
                leaf = jnp.zeros_like(leaf)
            leaves.append(leaf)
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(params), leaves)

    actor_key, critic_key = jax.random.split(jax.random.fold_in(rng, 1))
    actor = state["actor_ts"].replace(params=reinit(state["actor_ts"].params, 0.01, "action_mean", actor_key))
    critic_params = state["critic_ts"].params
    last = sorted(k for k in critic_params["params"] if k.startswith("Dense_"))[-1]  # the value head
    critic = state["critic_ts"].replace(params=reinit(critic_params, 1.0, last, critic_key))
    return {**state, "actor_ts": actor, "critic_ts": critic}
