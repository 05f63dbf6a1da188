"""The policy interface used by the evaluation runner."""

from __future__ import annotations

import inspect
from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Policy(Protocol):
    """A policy maps observations to actions in the env's action space.

    Required: ``name`` (the ``policy`` column of every record), ``action_mode`` (``"continuous"``:
    three numbers in [0, 1]; ``"discrete"``: an index into the 125-point grid) and ``act``, which
    must be deterministic given the policy's state.

    Optional hooks, called by the evaluation runner (:mod:`solarchain_eval.evaluation.rollout`)
    when the policy has them:

    - ``begin_run(run_seed)``: once per run seed, before its first episode (the Random baseline
      seeds its generator there);
    - ``begin_episode(*, env, episode, run_seed, episode_seed, start_hour)``: after each reset,
      before the first ``act`` (the Planner/Auditor wrapper plans the episode there). The env is
      passed only to a hook that declares an ``env`` parameter (or ``**kwargs``): a policy that
      must see no more than its observations (the LLM agent) leaves it out;
    - ``observe(info)``: after each step, with that step's ``info`` dict;
    - ``end_episode()``: after the last step; a returned dict is kept in the episode's
      ``extras`` (the wrapper returns its log rows and agentic metrics).

    A policy may also declare ``stateless = True``: its action depends on the observation only
    and ``act`` may be called from several threads, so its episodes can run concurrently
    (``evaluate --llm-concurrency``); without it, a run's episodes run in order.
    """

    name: str
    action_mode: str

    def begin_run(self, run_seed: int) -> None: ...

    def act(self, observation: np.ndarray) -> Any: ...


def hook_takes_env(hook: Any) -> bool:
    """Whether a ``begin_episode`` hook declares an ``env`` parameter (or takes ``**kwargs``)."""
    try:
        parameters = inspect.signature(hook).parameters.values()
    except (TypeError, ValueError):  # no signature to read (a builtin): pass the env as before
        return True
    return any(p.name == "env" or p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters)


def begin_episode(policy: Any, *, env: Any, episode: int, run_seed: int, episode_seed: int, start_hour: int) -> None:
    """Call ``policy``'s ``begin_episode`` hook, if it has one, with the env only if it asks for it."""
    hook = getattr(policy, "begin_episode", None)
    if hook is None:
        return
    context: dict[str, Any] = {
        "episode": episode,
        "run_seed": run_seed,
        "episode_seed": episode_seed,
        "start_hour": start_hour,
    }
    if hook_takes_env(hook):
        context["env"] = env
    hook(**context)
