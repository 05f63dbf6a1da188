"""Turn what a user brings into an agent the runner can drive.

:func:`as_agent` accepts an object with ``act(observation)`` (the :class:`~.base.Policy`
protocol), a plain function ``observation -> action``, or a Stable-Baselines3 model (anything
with ``predict(observation, deterministic=True)`` and an ``action_space``, sb3-contrib's
included). It returns a :class:`UserAgent`: the user's agent behind a thin shell that names it
(:mod:`.names`), exposes exactly the hooks the agent has, and guards every call into the user's
code: an exception (``SystemExit`` included), an action that is not valid as returned, or an
``end_episode`` value that is not a dict of numbers and short text (:mod:`.validation`) is an
:class:`AgentFailure`, one line naming the agent, to which the rollout adds the run seed,
episode and step.
"""

from __future__ import annotations

import copy
import functools
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np

from ..common.errors import UserAgentError
from ..config import BenchmarkConfig
from ..tasks.registry import get_task
from .names import name_problem
from .validation import AGENT_EXTRAS_KEY, agent_columns, continuous_problem, discrete_problem

#: The hooks the runner calls when an agent has them (see :class:`~.base.Policy`).
HOOKS = ("begin_run", "begin_episode", "observe", "end_episode", "close")
ACTION_MODES = ("continuous", "discrete")


def discrete_actions(config: Any, task: str | None = None) -> int:
    """Size of the discrete action grid: ``config.discrete_levels`` values for each of the task's levers
    (the solar market's three levers at 5 levels: 125)."""
    return int(config.discrete_levels) ** len(get_task(task).levers)


def __getattr__(name: str) -> Any:
    # DEFAULT_DISCRETE_ACTIONS, the grid's size under the default configuration, is worked out from
    # the default task on first use (through the task registry, not an import of the market).
    if name == "DEFAULT_DISCRETE_ACTIONS":
        return _default_grid()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: The benchmark's own policy classes (module.qualname). An object of one of these, passed to an
#: evaluation as an object, is driven as the registry builds it (no shell, its own ``end_episode``
#: extras, the env's decoding of its actions); every other object is a user's agent.
BUILTIN_POLICY_CLASSES = frozenset(
    {
        "solarchain_eval.market.baselines.StaticPolicy",
        "solarchain_eval.market.baselines.RandomPolicy",
        "solarchain_eval.market.baselines.MyopicPolicy",
        "solarchain_eval.agents.sb3.SB3Policy",
        "solarchain_eval.agents.jax_checkpoint.JaxPolicy",
        "solarchain_eval.governance.llm_agent.LLMAgent",
    }
)


@functools.cache
def _default_grid() -> int:
    return discrete_actions(BenchmarkConfig())


def is_builtin_policy(agent: Any) -> bool:
    """Whether ``agent`` is one of the benchmark's own policies (:data:`BUILTIN_POLICY_CLASSES`)."""
    cls = type(agent)
    return f"{cls.__module__}.{cls.__qualname__}" in BUILTIN_POLICY_CLASSES


class AgentError(UserAgentError, ValueError):
    """An agent that cannot take part as given: bad name, action mode, action or hook."""


class AgentFailure(AgentError):
    """A user's agent failed while it was driven: its code raised, or it returned something unusable.

    The message is one line: ``agent 'NAME': PROBLEM (run seed R, episode E, step S)``; the rollout
    fills the position (:meth:`at`) as the failure passes through it, and leaves out what it does
    not know (a failure while the agent is built has no position). ``user_error`` keeps the
    exception the user's code raised, for ``SOLARCHAIN_DEBUG=1`` to show its traceback.
    """

    def __init__(
        self,
        agent: str,
        problem: str,
        *,
        where: str = "",
        run_seed: int | None = None,
        episode: int | None = None,
        step: int | None = None,
        user_error: BaseException | None = None,
    ) -> None:
        super().__init__(problem)
        self.agent, self.problem, self.where = agent, problem, where
        self.run_seed, self.episode, self.step = run_seed, episode, step
        self.user_error = user_error

    def at(self, *, run_seed: int | None = None, episode: int | None = None, step: int | None = None) -> AgentFailure:
        """Fill in the parts of the position not known yet; returns ``self``."""
        self.run_seed = self.run_seed if self.run_seed is not None else run_seed
        self.episode = self.episode if self.episode is not None else episode
        self.step = self.step if self.step is not None else step
        return self

    def __str__(self) -> str:
        parts = [f"{label} {value}" for label, value in self._position() if value is not None]
        return f"agent '{self.agent}'{self.where}: {self.problem}" + (f" ({', '.join(parts)})" if parts else "")

    def _position(self) -> tuple[tuple[str, int | None], ...]:
        return (("run seed", self.run_seed), ("episode", self.episode), ("step", self.step))

    def __reduce__(self) -> tuple:
        # Failures cross process boundaries (grid workers); the user's exception may not pickle.
        state = {k: v for k, v in self.__dict__.items() if k != "user_error"}
        return (_rebuild_failure, (type(self), state))


def _rebuild_failure(cls: type[AgentFailure], state: dict[str, Any]) -> AgentFailure:
    failure = cls.__new__(cls)
    failure.__dict__.update(state, user_error=None)
    failure.args = (state.get("problem", ""),)
    return failure


def describe_exception(error: BaseException) -> str:
    """The exception's own last line (``Type: message``) with any line breaks folded: one line."""
    text = " ".join(str(error).split())
    if isinstance(error, SystemExit):
        return f"SystemExit({error.code!r}): the agent called sys.exit"
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


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
    """A user's agent as the runner drives it: named, with the agent's own hooks, every call guarded.

    Parameters
    ----------
    inner : object
        The agent (``act`` required; hooks optional).
    name : str
        The ``policy`` column of its records (:mod:`.names`).
    builtin : bool
        The benchmark's own policy under another name (``mine=static``): its actions' shape is
        checked, their values go to the environment as they are.
    discrete_actions : int, optional
        Size of the discrete grid (a discrete agent's index must be below it); default: the
        default configuration's.
    """

    def __init__(self, inner: Any, name: str, *, builtin: bool = False, discrete_actions: int | None = None) -> None:
        problem = name_problem(name)
        if problem is not None:
            raise AgentError(f"{problem}; name the agent with NAME=spec, or name= in Python")
        if not callable(getattr(inner, "act", None)):
            raise AgentError(f"agent '{name}': {type(inner).__name__} has no act(observation) method")
        mode = getattr(inner, "action_mode", "continuous")
        if mode not in ACTION_MODES:
            raise AgentError(f"agent '{name}': action_mode must be 'continuous' or 'discrete', not {mode!r}")
        self.inner = inner
        self.name = name
        self.action_mode = mode
        self.builtin = builtin
        # None: the grid of the default configuration and task
        self.discrete_actions = int(discrete_actions if discrete_actions is not None else _default_grid())
        self.stateless = bool(getattr(inner, "stateless", False))
        self._act = inner.act
        for hook in HOOKS:  # only the hooks the agent has, so the runner's getattr sees the same
            method = getattr(inner, hook, None)
            if callable(method):
                setattr(self, hook, self._guarded(hook, method))
        # SB3 models sample actions the environment clips (as in training): their range is not checked.
        self._check_range = not isinstance(inner, SB3ModelAgent)

    def act(self, observation: np.ndarray) -> Any:
        action = self.act_unchecked(observation)
        problem = self.action_problem(action)
        if problem is not None:
            raise AgentFailure(self.name, problem)
        return action

    def act_unchecked(self, observation: np.ndarray) -> Any:
        """The agent's action, its errors guarded, before :meth:`action_problem` (the isolated door's
        agent process leaves a numeric array's check to the evaluating process, which makes it anyway)."""
        return self._call("act", self._act, observation)

    def action_problem(self, action: Any) -> str | None:
        """What is wrong with ``action`` for this agent (None: nothing)."""
        if self.action_mode == "continuous":
            return continuous_problem(action, check_values=not self.builtin, check_range=self._check_range)
        return discrete_problem(action, self.discrete_actions)

    def _guarded(self, hook: str, method: Callable[..., Any]) -> Callable[..., Any]:
        if hook == "end_episode":

            def end_episode() -> dict[str, Any]:
                returned = self._call(hook, method)
                try:
                    columns = agent_columns(returned)
                except ValueError as error:
                    raise AgentFailure(self.name, str(error)) from None
                return {AGENT_EXTRAS_KEY: columns} if columns else {}

            return end_episode
        return lambda *args, **kwargs: self._call(hook, method, *args, **kwargs)

    def _call(self, hook: str, method: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """``method(*args, **kwargs)``; whatever it raises (``SystemExit`` included) as an :class:`AgentFailure`."""
        try:
            return method(*args, **kwargs)
        except AgentFailure:
            raise  # already one line naming the agent (an HTTP agent's own errors)
        except AgentError as error:
            if getattr(error, "names_its_agent", False):
                raise  # an isolated agent's line, which names the agent and its position itself
            raise AgentFailure(self.name, f"{hook}() raised {describe_exception(error)}", user_error=error) from error
        except (Exception, SystemExit) as error:
            raise AgentFailure(self.name, f"{hook}() raised {describe_exception(error)}", user_error=error) from error

    def __deepcopy__(self, memo: dict) -> UserAgent:
        # The guarded hooks are closures over this shell: a copy gets its own, bound to its own inner copy.
        twin = UserAgent(
            copy.deepcopy(self.inner, memo), self.name, builtin=self.builtin, discrete_actions=self.discrete_actions
        )
        memo[id(self)] = twin
        return twin

    def __repr__(self) -> str:
        return f"UserAgent({self.name!r}, {type(self.inner).__name__}, {self.action_mode})"


def as_agent(
    agent: Any,
    *,
    name: str | None = None,
    builtin: bool = False,
    discrete_actions: int | None = None,
) -> UserAgent:
    """The runner's view of a user's agent (see the module docstring).

    Parameters
    ----------
    agent : object, function or SB3 model
    name : str, optional
        Overrides the agent's own ``name`` (default: its ``name``, else its class or function name).
    builtin : bool
        ``agent`` is one of the benchmark's own policies (see :class:`UserAgent`).
    discrete_actions : int, optional
        Size of the discrete grid of the evaluation's configuration (:func:`discrete_actions`;
        default: the default configuration's).

    Raises
    ------
    AgentError
        The object is none of the accepted kinds, its name breaks the naming rule
        (:mod:`.names`), or it declares an unknown action mode.
    """
    if discrete_actions is None:
        discrete_actions = _default_grid()
    options = {"builtin": builtin, "discrete_actions": discrete_actions}
    if isinstance(agent, UserAgent):
        same = name in (None, agent.name) and (agent.builtin, agent.discrete_actions) == (builtin, discrete_actions)
        return agent if same else UserAgent(agent.inner, name or agent.name, **options)
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
    return UserAgent(inner, label, **options)
