"""Acting with a rejax checkpoint: rebuild the network, load its parameters, act deterministically.

The network is rebuilt by rejax's own ``create_agent`` from the rejax settings saved beside the
checkpoint (``train_config.json`` → ``rejax``), so the module is the one that was trained. The
deterministic action is the one Stable-Baselines3's ``predict(deterministic=True)`` takes:

- PPO (Gaussian policy): the mean, clipped to the action box;
- SAC (squashed Gaussian): ``loc + scale * tanh(mean)``;
- DQN: ``argmax`` of the Q-values.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization
from gymnax.environments import spaces

from ..tasks.base import observation_names_of
from ..tasks.registry import get_task


def task_shapes(task: str | None = None) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The observation's and the normalised action's shapes in ``task`` (default: the solar market's
    (12,) and (3,)): one entry per declared observation feature, one per lever."""
    market = get_task(task)
    names = observation_names_of(market)
    if names is None:
        raise ValueError(f"task {market.name!r} declares no observation_names: a JAX network cannot be sized for it")
    return (len(names),), (len(market.levers),)


class _SpacesOnly:
    """The two space methods that rejax's ``create_agent`` asks the environment for."""

    def __init__(self, action_mode: str, n_actions: int, task: str | None = None) -> None:
        self._action_mode, self._n_actions = action_mode, n_actions
        self._observation_shape, self._action_shape = task_shapes(task)

    def action_space(self, params: Any = None) -> spaces.Space:
        if self._action_mode == "discrete":
            return spaces.Discrete(self._n_actions)
        # every task's agent acts in the normalised box [0, 1] per lever
        return spaces.Box(0.0, 1.0, self._action_shape, jnp.float32)

    def observation_space(self, params: Any = None) -> spaces.Box:
        return spaces.Box(-jnp.inf, jnp.inf, self._observation_shape, jnp.float32)


def acting_module(
    algo: str, rejax_settings: dict[str, Any], action_mode: str, n_actions: int, task: str | None = None
) -> Any:
    """The flax module of ``algo``'s acting network (actor, or Q-network for DQN), as rejax builds it."""
    import rejax

    settings = copy.deepcopy(rejax_settings)
    agent = rejax.get_algo(algo).create_agent(settings, _SpacesOnly(action_mode, n_actions, task), None)
    return agent["agent"] if algo == "dqn" else agent["actor"]


def _deterministic(module: Any, algo: str) -> Callable[[Any, jax.Array], jax.Array]:
    """A function (params, obs batch) -> actions, the deterministic choice of the module docstring."""
    if algo == "dqn":
        return lambda params, obs: jnp.argmax(module.apply(params, obs), axis=-1)

    if algo == "sac":

        def squashed_mean(m: Any, obs: jax.Array) -> jax.Array:
            return m.action_loc + jnp.tanh(m._action_dist(obs).mean()) * m.action_scale

        return lambda params, obs: module.apply(params, obs, method=squashed_mean)

    def clipped_mean(m: Any, obs: jax.Array) -> jax.Array:
        low, high = m.action_range
        return jnp.clip(m._action_dist(obs).mean(), low, high)

    return lambda params, obs: module.apply(params, obs, method=clipped_mean)


class JaxActor:
    """A trained rejax network that maps (12,) observations to actions on the CPU.

    Parameters
    ----------
    algo : {"ppo", "sac", "dqn"}
    model_path : path
        ``jax_model.msgpack``: the acting network's parameters (flax msgpack).
    rejax_settings : dict
        The rejax keyword arguments the network was trained with (network sizes, activation).
    action_mode : {"continuous", "discrete"}
    n_actions : int
        Size of the discrete grid (DQN).
    task : str, optional
        The task whose env the network acts in (default: the solar market): its shapes.
    """

    def __init__(
        self,
        algo: str,
        model_path: Path,
        rejax_settings: dict[str, Any],
        action_mode: str,
        n_actions: int,
        task: str | None = None,
    ) -> None:
        self.algo = algo
        self.module = acting_module(algo, rejax_settings, action_mode, n_actions, task)
        self._observation_shape = task_shapes(task)[0]
        key, obs = jax.random.key(0), jnp.zeros((1, *self._observation_shape), jnp.float32)
        # The actors' __call__ also takes a key; the Q-network's does not.
        template = self.module.init(key, obs) if algo == "dqn" else self.module.init(key, obs, key)
        data = Path(model_path).read_bytes()
        try:
            self.params = serialization.from_bytes(template, data)
        except Exception as error:  # msgpack or a structure mismatch: say which file
            raise ValueError(f"cannot load {model_path} as a {algo.upper()} network: {error}") from None
        shapes = jax.tree.map(np.shape, template) == jax.tree.map(np.shape, self.params)
        if not shapes:
            raise ValueError(f"{model_path}: the network's parameter shapes differ from the {algo.upper()} settings")
        self._act = jax.jit(_deterministic(self.module, algo))

    def act_batch(self, observations: np.ndarray) -> np.ndarray:
        """Deterministic actions for a (B, observation size) batch of observations."""
        return np.asarray(self._act(self.params, jnp.asarray(observations, jnp.float32)))

    def act(self, observation: np.ndarray) -> Any:
        """The action for one observation: a float32 array (one value per lever), or an int index for DQN."""
        action = self.act_batch(np.asarray(observation, np.float32).reshape(1, *self._observation_shape))[0]
        return int(action) if self.algo == "dqn" else action.astype(np.float32)
