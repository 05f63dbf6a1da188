"""Roll policies out in the environment and collect per-step and per-episode records."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..agents.adapters import AgentFailure
from ..agents.base import Policy, is_privileged
from ..protocol import paper_episode_seeds
from ..tasks.base import Task
from ..tasks.registry import get_task

#: The solar market's per-step record columns (docs/metrics.md#per-step-record); each task declares its own.
STEP_FIELDS = get_task().step_fields


@dataclass
class EpisodeResult:
    """One evaluated episode: identifiers, per-step columns, city rewards and metrics."""

    policy: str
    setting: str
    run_seed: int
    episode: int
    episode_seed: int
    start_hour: int
    steps: dict[str, list]
    city_rewards: list[tuple[float, ...]]
    metrics: dict[str, float]
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return len(next(iter(self.steps.values()), ()))


def run_episode(
    env: Any,
    policy: Policy,
    *,
    episode_seed: int,
    setting: str,
    run_seed: int,
    episode: int,
    task: Task | None = None,
) -> EpisodeResult:
    """Run one full episode of ``task`` (default: the solar market) in ``env`` with ``policy`` acting deterministically.

    A user agent's failure (:class:`~solarchain_eval.agents.adapters.AgentFailure`) leaves with the
    run seed, episode and step it happened at (``begin_episode``: step 0; ``end_episode``: the last).
    """
    step = [0]
    try:
        return _run_episode(task or get_task(), env, policy, episode_seed, setting, run_seed, episode, step)
    except AgentFailure as failure:
        raise failure.at(run_seed=run_seed, episode=episode, step=step[0]) from failure.__cause__


def _run_episode(
    task: Task, env: Any, policy: Policy, episode_seed: int, setting: str, run_seed: int, episode: int, step: list[int]
) -> EpisodeResult:
    obs, reset_info = env.reset(seed=episode_seed)
    begin = getattr(policy, "begin_episode", None)
    if begin is not None:
        context = {
            "episode": episode,
            "run_seed": run_seed,
            "episode_seed": episode_seed,
            "start_hour": int(reset_info["episode_start_hour"]),
        }
        # Agents get the public context only; the benchmark's privileged components also the env.
        if is_privileged(policy):
            begin(env=env, **context)
        else:
            begin(**context)
    columns: dict[str, list] = {name: [] for name in task.step_fields}
    appenders = [(columns[name].append, name) for name in task.step_fields]
    extras = task.step_extras
    city_rewards: list[tuple[float, ...]] = []
    observe = getattr(policy, "observe", None)
    truncated = terminated = False
    while not (truncated or terminated):
        action = policy.act(obs)
        obs, _, terminated, truncated, info = env.step(action)
        for append, name in appenders:
            append(info[name])
        city_rewards.append(extras(info))
        if observe is not None:
            observe(info)
        step[0] += 1
    metrics = task.episode_metrics(columns, env)
    result = EpisodeResult(
        policy=policy.name,
        setting=setting,
        run_seed=run_seed,
        episode=episode,
        episode_seed=episode_seed,
        start_hour=int(reset_info["episode_start_hour"]),
        steps=columns,
        city_rewards=city_rewards,
        metrics=metrics,
    )
    finish = getattr(policy, "end_episode", None)
    if finish is not None:
        step[0] -= 1  # after the last step
        result.extras.update(finish() or {})
    return result


def begin_run(policy: Policy, run_seed: int) -> None:
    """Call the agent's optional ``begin_run`` hook."""
    hook = getattr(policy, "begin_run", None)
    if hook is not None:
        try:
            hook(run_seed)
        except AgentFailure as failure:
            raise failure.at(run_seed=run_seed) from failure.__cause__


def run_policy(
    env: Any,
    policy: Policy,
    *,
    setting: str,
    run_seeds: Sequence[int],
    episodes: int,
    episode_seeds: Callable[[int, int], list[int]] = paper_episode_seeds,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    task: Task | None = None,
) -> Iterable[EpisodeResult]:
    """Yield the episodes of ``policy`` in ``env`` (of ``task``, default the solar market) for each run seed
    (episodes in protocol order)."""
    if env.action_mode != policy.action_mode:
        raise ValueError(f"policy '{policy.name}' acts in {policy.action_mode} mode but the env is {env.action_mode}")
    for run_seed in run_seeds:
        begin_run(policy, run_seed)
        for episode, seed in enumerate(episode_seeds(run_seed, episodes)):
            result = run_episode(
                env, policy, episode_seed=seed, setting=setting, run_seed=run_seed, episode=episode, task=task
            )
            if on_episode is not None:
                on_episode(result)
            yield result
