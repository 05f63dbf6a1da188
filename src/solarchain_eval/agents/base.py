"""The agent interface the evaluation runner drives, and the rule of what an agent may see."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

#: The public context ``begin_episode`` receives, by keyword: the episode's index in its run, the
#: run seed, the seed the environment was reset with, and the dataset hour the episode starts at.
EPISODE_CONTEXT_KEYS = ("episode", "run_seed", "episode_seed", "start_hour")


@runtime_checkable
class Policy(Protocol):
    """An agent: it maps observations to actions in the environment's action space.

    Required: ``act(observation)``, which must be deterministic given the agent's state. The
    runner also reads ``name`` (the ``policy`` column of every record; the class name when
    absent) and ``action_mode`` (``"continuous"``, the default: three numbers in [0, 1];
    ``"discrete"``: an index into the 125-point grid).

    Optional hooks, called by the evaluation runner (:mod:`solarchain_eval.evaluation.rollout`)
    when the agent has them:

    - ``begin_run(run_seed)``: once per run seed, before its first episode (the Random baseline
      seeds its generator there);
    - ``begin_episode(*, episode, run_seed, episode_seed, start_hour)``: after each reset,
      before the first ``act``, with the episode's public context (:data:`EPISODE_CONTEXT_KEYS`);
    - ``observe(info)``: after each step, with that step's ``info`` dict (the outcome the market
      publishes: reward, matched energy, prices, the executed action, ...);
    - ``end_episode()``: after the last step; a returned dict is kept in the episode's ``extras``;
    - ``close()``: once, when the evaluation ends (release connections, files).

    An agent may also declare ``stateless = True``: its action depends on the observation only
    and ``act`` may be called from several threads, so its episodes can run concurrently
    (``evaluate --llm-concurrency``); without it, a run's episodes run in order.

    Fairness: an agent is handed observations, the step ``info`` and the public context, never
    the environment or its hourly table (future hours, price shocks); the only components handed
    the environment are the benchmark's own *privileged* ones (:func:`is_privileged`). An agent
    in the evaluating process can still reach the environment through the interpreter (a stack
    walk, ``gc``); an isolated one cannot (:func:`access_label`).
    """

    name: str
    action_mode: str

    def act(self, observation: np.ndarray) -> Any: ...


def is_privileged(policy: Any) -> bool:
    """Whether the runner hands ``policy`` the environment in ``begin_episode(env=...)``.

    Only the benchmark's own components qualify (the Planner/Auditor wrapper, whose planner
    reads the episode's hours ahead and whose auditor evaluates counterfactual steps): the class
    declares ``privileged = True`` *and* is defined inside this package. Their rows are labelled
    "privileged" in the run's metadata and tables, so they are never mistaken for agents that
    saw only what the market publishes.
    """
    cls = type(policy)
    return bool(getattr(cls, "privileged", False)) and cls.__module__.startswith("solarchain_eval.")


#: The access labels of a run's rows (``policy_access`` in run_metadata.json), see :func:`access_label`.
ACCESS_LABELS = ("isolated", "in-process", "privileged")


def is_isolated(policy: Any) -> bool:
    """Whether ``policy`` acts from another process, so nothing it runs reaches the environment.

    True for the benchmark's own shells that declare ``isolated = True``: the isolated door
    (:class:`~solarchain_eval.agents.isolated.IsolatedAgent`) and the HTTP door
    (:class:`~solarchain_eval.agents.http_agent.HttpAgent`), also behind the
    :class:`~solarchain_eval.agents.adapters.UserAgent` shell. A user's class declaring it is not.
    """
    from .adapters import UserAgent  # adapters is imported lazily: it is the heavier module

    inner = policy.inner if isinstance(policy, UserAgent) else policy
    cls = type(inner)
    return bool(getattr(cls, "isolated", False)) and cls.__module__.startswith("solarchain_eval.")


def access_label(policy: Any) -> str:
    """What a row's agent could reach (:data:`ACCESS_LABELS`).

    ``"privileged"``: it is handed the environment (:func:`is_privileged`); ``"isolated"``: it
    runs in another process and receives only the public observation, step info and context
    (:func:`is_isolated`); ``"in-process"``: it receives only those too, but runs in the
    evaluating process, where its code could reach the environment by other means (a stack
    walk, ``gc``). The built-in baselines and learned policies run in-process.
    """
    if is_privileged(policy):
        return "privileged"
    return "isolated" if is_isolated(policy) else "in-process"
