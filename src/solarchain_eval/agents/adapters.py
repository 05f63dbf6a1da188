"""Turn what a user brings into an agent the runner can drive.

:func:`as_agent` accepts an object with ``act(observation)`` (the :class:`~.base.Policy`
protocol), a plain function ``observation -> action``, or a Stable-Baselines3 model (anything
with ``predict(observation, deterministic=True)`` and an ``action_space``, sb3-contrib's
included). It returns a :class:`UserAgent`: the user's agent behind a thin shell that names it,
exposes exactly the hooks the agent has, and checks the shape of every action it returns, so a
wrong action is a one-line error naming the agent and the step instead of a numpy traceback.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numpy as np

#: The hooks the runner calls when an agent has them (see :class:`~.base.Policy`).
HOOKS = ("begin_run", "begin_episode", "observe", "end_episode", "close")
ACTION_MODES = ("continuous", "discrete")


class AgentError(ValueError):
    """An agent that cannot take part as given: bad name, action mode, action or hook."""


def _name_of(agent: Any) -> str | None:
    name = getattr(agent, "name", None)
    return name if isinstance(name, str) and name.strip() else None


class SB3ModelAgent:
    """A Stable-Baselines3 (or sb3-contrib) model acting with ``predict(obs, deterministic=True)``.

    The action mode follows the model's action space (``Discrete`` -> ``"discrete"``, a ``Box``
    of three -> ``"continuous"``). Recurrent models (``RecurrentPPO``) keep their hidden state
    within an episode and start each episode afresh. ``obs_normalizer`` (a loaded
    ``VecNormalize``) normalises observations the way the model saw them in training.
    """

    def __init__(self, model: Any, *, name: str | None = None, obs_normalizer: Any = None) -> None:
        self.model = model
        self.name = name or type(model).__name__.lower()
        self.obs_normalizer = obs_normalizer
        space = getattr(model, "action_space", None)
        if space is not None and getattr(space, "n", None) is not None:
            self.action_mode = "discrete"
        else:
            self.action_mode = "continuous"
        # sb3-contrib's recurrent policies take (obs, state, episode_start) and return a new state.
        self._recurrent = hasattr(getattr(model, "policy", None), "lstm_actor")
        self.stateless = not self._recurrent and obs_normalizer is None
        self._state: Any = None
        self._episode_start = np.ones((1,), dtype=bool)

    def begin_episode(self, **_context: Any) -> None:
        self._state = None
        self._episode_start = np.ones((1,), dtype=bool)

    def act(self, observation: np.ndarray) -> Any:
        if self.obs_normalizer is not None:
            observation = self.obs_normalizer.normalize_obs(observation)
        if not self._recurrent:
            action, _ = self.model.predict(observation, deterministic=True)
            return action
        action, self._state = self.model.predict(
            observation, state=self._state, episode_start=self._episode_start, deterministic=True
        )
        self._episode_start = np.zeros((1,), dtype=bool)
        return action


class FunctionAgent:
    """A plain function ``observation -> action`` as a stateless agent."""

    def __init__(self, function: Callable[[np.ndarray], Any], *, name: str, action_mode: str = "continuous") -> None:
        self.function = function
        self.name = name
        self.action_mode = action_mode
        self.stateless = True

    def act(self, observation: np.ndarray) -> Any:
        return self.function(observation)


def is_sb3_model(agent: Any) -> bool:
    return callable(getattr(agent, "predict", None)) and hasattr(agent, "action_space") and not hasattr(agent, "act")


def is_observation_function(agent: Any) -> bool:
    """A callable taking exactly one required positional argument (and not a class)."""
    if inspect.isclass(agent) or not callable(agent) or hasattr(agent, "act"):
        return False
    try:
        parameters = inspect.signature(agent).parameters.values()
    except (TypeError, ValueError):
        return False
    positional = [
        p
        for p in parameters
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is inspect.Parameter.empty
    ]
    return len(positional) == 1


class UserAgent:
    """A user's agent as the runner drives it: named, with the agent's own hooks, actions checked.

    Parameters
    ----------
    inner : object
        The agent (``act`` required; hooks optional).
    name : str
        The ``policy`` column of its records.
    """

    def __init__(self, inner: Any, name: str) -> None:
        if not callable(getattr(inner, "act", None)):
            raise AgentError(f"agent '{name}': {type(inner).__name__} has no act(observation) method")
        mode = getattr(inner, "action_mode", "continuous")
        if mode not in ACTION_MODES:
            raise AgentError(f"agent '{name}': action_mode must be 'continuous' or 'discrete', not {mode!r}")
        self.inner = inner
        self.name = name
        self.action_mode = mode
        self.stateless = bool(getattr(inner, "stateless", False))
        self._act = inner.act
        for hook in HOOKS:  # only the hooks the agent has, so the runner's getattr sees the same
            method = getattr(inner, hook, None)
            if callable(method):
                setattr(self, hook, method)
        self._check = _check_continuous if mode == "continuous" else _check_discrete

    def act(self, observation: np.ndarray) -> Any:
        action = self._act(observation)
        problem = self._check(action)
        if problem is not None:
            raise AgentError(f"agent '{self.name}': {problem}")
        return action

    def __repr__(self) -> str:
        return f"UserAgent({self.name!r}, {type(self.inner).__name__}, {self.action_mode})"


def _check_continuous(action: Any) -> str | None:
    try:
        shape = np.shape(action)
    except (TypeError, ValueError):
        return f"act() returned {type(action).__name__}; a continuous action is three numbers in [0, 1]"
    if shape not in ((3,), (1, 3)):
        return f"act() returned an action of shape {shape}; a continuous action has shape (3,)"
    return None


def _check_discrete(action: Any) -> str | None:
    value = np.asarray(action)
    if value.size != 1 or not np.issubdtype(value.dtype, np.integer):
        return f"act() returned {action!r}; a discrete action is one integer index"
    return None


def as_agent(agent: Any, *, name: str | None = None) -> UserAgent:
    """The runner's view of a user's agent (see the module docstring).

    Parameters
    ----------
    agent : object, function or SB3 model
    name : str, optional
        Overrides the agent's own ``name`` (default: its ``name``, else its class or function name).

    Raises
    ------
    AgentError
        The object is none of the accepted kinds, or declares an unknown action mode.
    """
    if isinstance(agent, UserAgent):
        return agent if name in (None, agent.name) else UserAgent(agent.inner, name)
    if is_sb3_model(agent):
        inner: Any = SB3ModelAgent(agent, name=name)
    elif is_observation_function(agent):
        label = name or getattr(agent, "__name__", None) or type(agent).__name__
        inner = FunctionAgent(agent, name=label, action_mode=getattr(agent, "action_mode", "continuous"))
    elif callable(getattr(agent, "act", None)):
        inner = agent
    else:
        raise AgentError(
            f"cannot use {type(agent).__name__} as an agent: give an object with act(observation), "
            "a function observation -> action, or a Stable-Baselines3 model"
        )
    label = name or _name_of(inner) or type(inner).__name__
    return UserAgent(inner, label)
