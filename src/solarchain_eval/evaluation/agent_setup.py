"""The evaluation's agents: built from a spec's policies, and checked before any work.

:func:`make_policies` builds the agents a run drives; :func:`check_agents` (and
:func:`check_agent_requests`, for requests made elsewhere) builds them and tries each user agent's
first action, so that a broken agent is reported before a run directory is staged.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from ..agents.adapters import AgentFailure, UserAgent
from ..agents.base import Policy
from ..agents.build import build_agents
from ..agents.isolated import IsolatedAgent
from ..agents.request import AgentContext, AgentRequest, agent_requests
from ..protocol import PAPER_SEEDS, paper_episode_seeds
from ..tasks.registry import get_task
from .reserved import check_reserved
from .rollout import begin_run
from .run_spec import EvaluationSpec, resolved_config


def make_policies(spec: EvaluationSpec, stack: ExitStack | None = None) -> list[Policy]:
    """The spec's agents, built by :func:`~solarchain_eval.agents.build.build_agents` from one
    request each (:func:`agent_requests_of`), with the spec's config (its reward setting applied).

    Agents built here are closed by ``stack`` when given (their ``close`` hook); agents the caller
    passed in are the caller's to close.

    Raises
    ------
    AgentSpecError
        A spec that cannot be built, or two agents with one name (their episodes would pool).
    FileNotFoundError
        A learned policy without a trained model (the message lists where it looked).
    """
    return build_agents(agent_requests_of(spec), _agent_context(spec), stack=stack, check_name=check_reserved)


def agent_requests_of(spec: EvaluationSpec) -> list[AgentRequest]:
    """One :class:`~solarchain_eval.agents.request.AgentRequest` per policy of ``spec``, with its options."""
    return agent_requests(
        spec.policies,
        models=spec.models,
        agent_args=spec.agent_args,
        vecnormalize=spec.vecnormalize,
        llm=spec.llm,
        isolate=spec.isolate,
        task=spec.task,
    )


def _agent_context(spec: EvaluationSpec) -> AgentContext:
    return AgentContext(resolved_config(spec), spec.task)


def check_agents(spec: EvaluationSpec) -> list[str]:
    """Build the spec's agents and try each user agent's first action, then release them.

    Run before any work so that an import error, a missing model, a name used twice or an
    action of the wrong shape is reported at once. The first action is taken by a *copy* of the
    agent (its state is not advanced); agents that cannot be copied (an open connection) are
    tried on their first real step instead.

    Returns
    -------
    list of str
        The agents' names (the ``policy`` column of their records), in the spec's order.
    """
    return check_agent_requests(
        agent_requests_of(spec),
        _agent_context(spec),
        data_dir=spec.data_dir,
        run_seed=int(spec.run_seeds[0]),
        episode_seeds=spec.episode_seeds,
    )


def check_agent_requests(
    requests: Sequence[AgentRequest],
    context: AgentContext,
    *,
    data_dir: Path | None = None,
    run_seed: int = PAPER_SEEDS[0],
    episode_seeds: Callable[[int, int], list[int]] = paper_episode_seeds,
) -> list[str]:
    """:func:`check_agents` for agent requests: build them, try each user agent's first action on
    ``data_dir`` (None: the config's dataset) in the first episode of ``run_seed``, release them.

    Returns
    -------
    list of str
        The agents' names, in the requests' order.
    """
    task = get_task(context.task)
    table = task.load_data(task.data_dir(data_dir, context.config))
    with ExitStack() as stack:
        agents = build_agents(requests, context, stack=stack, check_name=check_reserved)
        for agent in agents:
            if isinstance(agent, UserAgent):
                _try_first_action(agent, context, table, int(run_seed), episode_seeds)
        return [agent.name for agent in agents]


def _try_first_action(
    agent: UserAgent,
    context: AgentContext,
    table: Any,
    run_seed: int,
    episode_seeds: Callable[[int, int], list[int]],
) -> None:
    try:
        # An isolated agent is a copy already (in its process), which this check then closes.
        trial = agent if isinstance(agent.inner, IsolatedAgent) else copy.deepcopy(agent)
    except Exception:  # an agent holding a socket, a lock, a model server: tried on its first step
        return
    env = get_task(context.task).make_env(context.config, table, action_mode=trial.action_mode)
    (episode_seed,) = episode_seeds(run_seed, 1)
    obs, info = env.reset(seed=episode_seed)
    try:
        begin_run(trial, run_seed)
        begin = getattr(trial, "begin_episode", None)
        if begin is not None:
            begin(episode=0, run_seed=run_seed, episode_seed=episode_seed, start_hour=int(info["episode_start_hour"]))
        env.step(trial.act(obs))  # the shell checks the action as returned
    except AgentFailure as failure:
        raise failure.at(run_seed=run_seed, episode=0, step=0) from failure.user_error
