"""Re-running one policy's chosen episodes under a run's rebuilt protocol (:class:`Rerun`) and
comparing each with its recorded ``metrics.csv`` row, cell by cell (:func:`rerun_policy`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from ..agents.base import Policy
from ..governance.factory import Governance
from ..tasks.base import Task
from .inflight import is_stateless
from .records import METRICS_FILE
from .rollout import begin_run, run_episode
from .verify_checks import Difference, first_difference, written_row
from .verify_outcome import DIFFERS, VERIFIED, PolicyVerification
from .verify_plan import replay_plan


@dataclass
class Rerun:
    """What one policy's re-run needs (the run's protocol, rebuilt)."""

    task: Task
    config: Any  # the task's configuration
    table: Any  # the task's dataset (the solar market: an hourly table; None for a task without one)
    setting: str
    run_seeds: list[int]
    episodes: int
    episode_seeds: Callable[[int, int], list[int]]
    #: One agent carried through all run seeds (the run was evaluated in order), else one per run seed.
    carry_over: bool
    governance: Governance | None
    recorded: dict[tuple[str, int, int], dict[str, str]]


def rerun_policy(
    name: str,
    base: Policy,
    build: Callable[[], Policy],
    chosen: Sequence[tuple[int, int]],
    rerun: Rerun,
) -> PolicyVerification:
    """Re-run ``chosen`` episodes of one policy (:func:`replay_plan`) and compare them with the recorded rows.

    ``base`` is a freshly built agent and ``build`` builds another: a stateful agent of a run
    that ran each run seed on its own agent (``--llm-concurrency``) gets a fresh one per run seed.
    """
    stateless = is_stateless(base)
    plan = replay_plan(chosen, rerun.run_seeds, rerun.episodes, stateless=stateless, carry_over=rerun.carry_over)
    wanted = set(chosen)
    compared = replayed = 0
    env: Any = None
    for index, (run_seed, episodes) in enumerate(plan):
        agent = base if stateless or rerun.carry_over or index == 0 else build()
        policy = rerun.governance.wrap(agent) if rerun.governance is not None else agent
        if env is None:
            env = rerun.task.make_env(rerun.config, rerun.table, action_mode=policy.action_mode)
        seeds = rerun.episode_seeds(run_seed, rerun.episodes)
        begin_run(policy, run_seed)
        for episode in episodes:
            result = run_episode(
                env,
                policy,
                episode_seed=seeds[episode],
                setting=rerun.setting,
                run_seed=run_seed,
                episode=episode,
                task=rerun.task,
            )
            if (run_seed, episode) not in wanted:
                replayed += 1
                continue
            recorded = rerun.recorded.get((name, run_seed, episode))
            if recorded is None:
                missing = Difference(run_seed, episode, "(row)", f"(none in {METRICS_FILE})", "(an episode)")
                return PolicyVerification(name, DIFFERS, compared, replayed, missing)
            difference = first_difference(recorded, written_row(result, rerun.task), run_seed, episode)
            if difference is not None:
                return PolicyVerification(name, DIFFERS, compared, replayed, difference)
            compared += 1
    return PolicyVerification(name, VERIFIED, compared, replayed)
