"""Where the JAX backend changes rejax to follow Stable-Baselines3 (docs/jax.md lists the rest).

rejax has no setting for these, so :func:`sb3_variant` subclasses its algorithm: SB3's
optimiser, initialisation and bootstrapping at the time limit for all three algorithms, and
SB3's value loss for PPO.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import jax
import numpy as np

#: Adam's epsilon in SB3: PPO's policies use 1e-5, SAC and DQN torch's default 1e-8.
ADAM_EPS = {"ppo": 1e-5, "sac": 1e-8, "dqn": 1e-8}

#: How each algorithm bootstraps when the 24th hour truncates the episode (SB3's way).
TIME_LIMIT = {
    "ppo": "bootstrapped: reward + gamma * V(terminal obs) at a truncation, which ends GAE there",
    "sac": "bootstrapped: the buffer stores the terminal obs as next obs and done False at a truncation",
    "dqn": "bootstrapped: the buffer stores the terminal obs as next obs and done False at a truncation",
}

#: SB3's SAC and DQN networks keep torch's default ``nn.Linear`` initialisation.
TORCH_INIT = "torch nn.Linear default: kernels and biases uniform in +-1/sqrt(fan_in)"

#: SAC's and DQN's minibatches (:mod:`.replay`; kept here so that reading it needs no rejax).
REPLAY_SAMPLING = "uniform with replacement among the stored transitions (SB3's ReplayBuffer.sample)"

#: Where this backend changes rejax to follow SB3 (recorded in each model's identity).
SB3_ALIGNMENT = {
    "ppo": {
        "gradient_clip": "global norm",
        "adam_eps": 1e-5,
        "value_loss": "unclipped, vf_coef * mean squared error",
        "init": "orthogonal: hidden gain sqrt(2), action mean 0.01, value 1; zero biases",
        "time_limit": TIME_LIMIT["ppo"],
    },
    **{
        algo: {
            "gradient_clip": "global norm",
            "adam_eps": 1e-8,
            "init": TORCH_INIT,
            "time_limit": TIME_LIMIT[algo],
            "replay_sampling": REPLAY_SAMPLING,
        }
        for algo in ("sac", "dqn")
    },
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
    - The initialisation: for PPO SB3's ``ortho_init`` (:func:`_orthogonal_ppo`), for SAC and
      DQN torch's default (:func:`_torch_default_init`), instead of flax's LeCun-normal kernels
      and zero biases (whose kernels are √3 times wider than torch's).
    - The time limit: rejax treats gymnax's ``done`` as the end of the return; SB3 bootstraps
      where an episode is truncated (the env's ``info["truncated"]``, from the true last
      observation ``info["terminal_obs"]``). PPO adds γ·V(terminal obs) to the last reward
      (SB3's ``collect_rollouts``) and GAE stops there as before (:func:`_bootstrapped_rollout`);
      SAC and DQN store the terminal observation as the transition's next observation with
      done False (SB3's ``handle_timeout_termination``; :func:`_step_for_buffer`).
    - The replay minibatches (SAC, DQN): SB3 draws them uniformly with replacement; rejax
      without replacement, at a cost that grows with the buffer (:mod:`.replay`).

    Not an alignment, but here because this is where rejax's state is defined: the train state
    also carries the training episodes' returns (``episode_returns``, :mod:`.jax_episodes`),
    which the trainer reports between chunks; they only read the rewards.
    """
    import jax.numpy as jnp
    import optax
    import rejax
    from flax.training.train_state import TrainState
    from rejax.algos.algorithm import register_init

    base = rejax.get_algo(algo)

    class SB3Variant(base):  # type: ignore[misc, valid-type]
        @register_init
        def initialize_training_returns(self, rng):
            # rejax calls the inits in name order, each with the next split of the key: this name
            # sorts last, so every other part of the state gets the key it had without it.
            from .jax_episodes import EpisodeReturns

            return {"episode_returns": EpisodeReturns.empty(self.num_envs)}

        @register_init
        def initialize_network_params(self, rng):
            state = super().initialize_network_params(rng)
            state = _orthogonal_ppo(state, rng) if algo == "ppo" else _torch_default_init(state, rng)
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

            collect_trajectories = _bootstrapped_rollout

        else:

            @register_init
            def initialize_replay_buffer(self, rng):
                # the same name as rejax's, so it replaces it and the other inits' keys stay as they were
                from .jax_replay import SB3ReplayBuffer

                return {"replay_buffer": SB3ReplayBuffer.empty(self.buffer_size, self.obs_space, self.action_space)}

            @property
            def vmap_step(self):
                return _step_for_buffer(jax.vmap(self.env.step, in_axes=(0, 0, 0, None)))

            def collect_transitions(self, ts, *args, **kwargs):
                # rejax's, with the buffer's transitions from _step_for_buffer; then the
                # observation the next action is chosen from is the env's own again: after an
                # auto-reset the new episode's first (gymnax's step returns get_obs(state)).
                _check_unnormalised(self)
                ts, batch = super().collect_transitions(ts, *args, **kwargs)
                observe = jax.vmap(self.env.get_obs, in_axes=(0, None))
                return ts.replace(last_obs=observe(ts.env_state, self.env_params)), batch

            def train_iteration(self, ts):
                # The episode returns, from the rewards the iteration stored in the buffer. Summed
                # inside collect_transitions, they make XLA compile the step differently and the
                # trained networks change in their last bits; read back here, they do not.
                ts = super().train_iteration(ts)
                buffer = ts.replay_buffer
                rows = (buffer.index - self.num_envs + jnp.arange(self.num_envs)) % buffer.size
                ended = ts.env_state.time == 0
                return ts.replace(episode_returns=ts.episode_returns.record(buffer.data.reward[rows], ended))

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


def _check_unnormalised(algo: Any) -> None:
    """The time-limit bootstrap below feeds raw observations and rewards (SB3's setting here)."""
    if getattr(algo, "normalize_observations", False) or getattr(algo, "normalize_rewards", False):
        raise ValueError("the SB3 time-limit bootstrap does not support rejax's observation or reward normalisation")


def _bootstrapped_rollout(self: Any, ts: Any) -> tuple[Any, Any]:
    """rejax PPO's ``collect_trajectories`` with SB3's bootstrap at a truncation.

    SB3's ``OnPolicyAlgorithm.collect_rollouts`` adds γ·V(terminal obs), with the rollout's own
    critic, to the reward of a step whose episode the time limit cut; the step stays ``done``,
    so GAE does not bootstrap from the (reset) next observation. Otherwise as rejax's.
    """
    import jax.numpy as jnp
    from rejax.algos.ppo import Trajectory

    _check_unnormalised(self)
    space = self.env.action_space(self.env_params)

    def env_step(ts: Any, unused: Any) -> tuple[Any, Any]:
        rng, new_rng = jax.random.split(ts.rng)
        ts = ts.replace(rng=rng)
        rng_steps, rng_action = jax.random.split(new_rng, 2)
        rng_steps = jax.random.split(rng_steps, self.num_envs)
        unclipped_action, log_prob = self.actor.apply(
            ts.actor_ts.params, ts.last_obs, rng_action, method="action_log_prob"
        )
        value = self.critic.apply(ts.critic_ts.params, ts.last_obs)
        action = unclipped_action if self.discrete else jnp.clip(unclipped_action, space.low, space.high)
        next_obs, env_state, reward, done, info = self.vmap_step(rng_steps, ts.env_state, action, self.env_params)
        terminal_value = self.critic.apply(ts.critic_ts.params, info["terminal_obs"])
        reward = jnp.where(info["truncated"], reward + self.gamma * terminal_value, reward)
        transition = Trajectory(ts.last_obs, unclipped_action, log_prob, reward, value, done)
        ts = ts.replace(
            env_state=env_state, last_obs=next_obs, last_done=done, global_step=ts.global_step + self.num_envs
        )
        return ts, transition

    start = ts
    ts, trajectories = jax.lax.scan(env_step, ts, None, self.num_steps)
    return ts.replace(episode_returns=_rollout_returns(self, start, trajectories)), trajectories


def _rollout_returns(self: Any, start: Any, trajectories: Any) -> Any:
    """The episode returns after a PPO rollout, from the env's own rewards (without the bootstrap).

    The rollout's rewards carry the bootstrap at truncations, so the env is stepped again from
    the rollout's first state with its keys and actions. Summing the rewards inside the rollout
    instead makes XLA compile it differently, and the trained networks would change in their
    last bits; this way the training is the same computation as without the record.
    """
    import jax.numpy as jnp

    space = self.env.action_space(self.env_params)

    def replay(carry: tuple[Any, Any, Any], action: Any) -> tuple[tuple[Any, Any, Any], None]:
        rng, env_state, returns = carry
        rng, new_rng = jax.random.split(rng)  # the key schedule of env_step above
        rng_steps, _ = jax.random.split(new_rng, 2)
        rng_steps = jax.random.split(rng_steps, self.num_envs)
        action = action if self.discrete else jnp.clip(action, space.low, space.high)
        _, env_state, reward, done, _ = self.vmap_step(rng_steps, env_state, action, self.env_params)
        return (rng, env_state, returns.record(reward, done)), None

    (_, _, returns), _ = jax.lax.scan(replay, (start.rng, start.env_state, start.episode_returns), trajectories.action)
    return returns


def _step_for_buffer(step: Any) -> Any:
    """A vmapped gymnax step returning what SB3's replay buffer stores at a truncation.

    SB3's buffer with ``handle_timeout_termination`` stores the true last observation as the
    next observation and counts a truncation as not done, so the target bootstraps from it.
    rejax's ``collect_transitions`` uses one array for the buffer's next observation and for
    the observation the next action is chosen from; this step hands it the terminal one (and
    done only where an episode terminated), and ``collect_transitions`` puts the env's back.
    """

    def step_for_buffer(keys: Any, state: Any, action: Any, params: Any) -> tuple[Any, ...]:
        _, state, reward, done, info = step(keys, state, action, params)
        return info["terminal_obs"], state, reward, done & ~info["truncated"], info

    return step_for_buffer


def _torch_default_init(state: dict[str, Any], rng: jax.Array) -> dict[str, Any]:
    """torch's default ``nn.Linear`` initialisation (SB3's SAC and DQN): every kernel and bias
    uniform in ±1/√fan_in (``kaiming_uniform_(a=√5)``); target networks start as copies.

    Works on every dense layer of the train states' parameters, including SAC's twin critics
    stacked along a leading axis (the fan-in is a kernel's second-to-last dimension).
    """
    from flax.training.train_state import TrainState

    def reinit(params: Any, key: jax.Array) -> Any:
        flat = jax.tree_util.tree_flatten_with_path(params)[0]
        fan_in = {jax.tree_util.keystr(path[:-1]): leaf.shape[-2] for path, leaf in flat if path[-1].key == "kernel"}
        keys = iter(jax.random.split(key, len(flat)))
        leaves = []
        for path, leaf in flat:
            bound = 1.0 / np.sqrt(fan_in[jax.tree_util.keystr(path[:-1])])
            leaves.append(jax.random.uniform(next(keys), leaf.shape, leaf.dtype, -bound, bound))
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(params), leaves)

    key = jax.random.fold_in(rng, 2)
    out = dict(state)
    for i, name in enumerate(sorted(k for k, v in state.items() if isinstance(v, TrainState) and k != "alpha_ts")):
        out[name] = state[name].replace(params=reinit(state[name].params, jax.random.fold_in(key, i)))
    for ts_name, target in (("q_ts", "q_target_params"), ("critic_ts", "critic_target_params")):
        if target in out:
            out[target] = out[ts_name].params
    return out
