"""Several episodes in flight on threads (``evaluate --llm-concurrency N``).

An agentic episode spends most of its time waiting for the Planner's and the Auditor's model
calls; with N episodes in flight a server that answers requests in parallel (vLLM, OpenAI,
llama.cpp's ``llama-server -np N``) is kept busy. The results are those of the sequential
runner, in the same order, whatever order the threads finish in:

- every task has its own environment (one per thread and action mode) and its own Planner/
  Auditor wrapper, so no episode state is shared;
- a policy that declares ``stateless = True`` (its action depends on the observation only, and
  it is safe to call from several threads: Static, Myopic, the trained SB3 models) has each of
  its episodes run as a separate task; any other policy (the Random baseline draws from one
  generator across a run's episodes) has each run seed's episodes run in order, in one task,
  on a private copy of the policy;
- model replies must not depend on the order requests arrive in (temperature 0 and a fixed
  seed, or a record/replay cache), as for any reproducible run.
"""

from __future__ import annotations

import copy
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

from ..agents.base import Policy
from ..tasks.base import Task as Market
from .rollout import EpisodeResult, begin_run, run_episode


@dataclass(frozen=True)
class Task:
    """Episodes of one policy and run seed that run in order on one thread."""

    policy_index: int
    run_seed: int
    episodes: tuple[tuple[int, int], ...]  # (episode index, episode seed)


def is_stateless(policy: Policy) -> bool:
    """Whether ``policy`` declares that its episodes may run in any order and concurrently."""
    return bool(getattr(policy, "stateless", False))


def plan_tasks(
    policies: Sequence[Policy],
    run_seeds: Sequence[int],
    episodes: int,
    episode_seeds: Callable[[int, int], list[int]],
) -> list[Task]:
    """The tasks in protocol order (policy, run seed, episode)."""
    tasks = []
    for index, policy in enumerate(policies):
        for run_seed in run_seeds:
            numbered = tuple(enumerate(episode_seeds(run_seed, episodes)))
            if is_stateless(policy):
                tasks.extend(Task(index, int(run_seed), (item,)) for item in numbered)
            else:
                tasks.append(Task(index, int(run_seed), numbered))
    return tasks


def run_in_flight(
    policies: Sequence[Policy],
    make_env: Callable[[str], Any],
    *,
    setting: str,
    run_seeds: Sequence[int],
    episodes: int,
    episode_seeds: Callable[[int, int], list[int]],
    workers: int,
    wrap: Callable[[Policy], Policy] | None = None,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    market: Market | None = None,
) -> list[EpisodeResult]:
    """Evaluate like :func:`~.rollout.run_policy` for each policy, ``workers`` tasks at a time.

    Parameters
    ----------
    policies : sequence of Policy
        Base policies (unwrapped).
    make_env : callable
        ``make_env(action_mode)`` builds a fresh environment (one per thread and mode).
    wrap : callable, optional
        Wraps a task's base policy (the Planner/Auditor layer); called once per task.
    on_episode : callable, optional
        Called with each finished episode, under a lock, in completion order (progress bars).
    market : Task, optional
        The market the environments are of (:class:`~solarchain_eval.tasks.base.Task`; default: the solar market).

    Returns
    -------
    list of EpisodeResult
        In protocol order, as the sequential runner returns them.

    Raises
    ------
    Exception
        The first error of any task; the tasks not yet started are cancelled and the running
        ones stop after their current episode.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    tasks = plan_tasks(policies, run_seeds, episodes, episode_seeds)
    local = threading.local()
    lock = threading.Lock()
    stop = threading.Event()

    def env_for(mode: str) -> Any:
        envs = getattr(local, "envs", None)
        if envs is None:
            envs = local.envs = {}
        if mode not in envs:
            envs[mode] = make_env(mode)
        return envs[mode]

    def run_task(task: Task) -> list[EpisodeResult]:
        base = policies[task.policy_index]
        base = base if is_stateless(base) else copy.deepcopy(base)
        policy = wrap(base) if wrap is not None else base
        env = env_for(policy.action_mode)
        begin_run(policy, task.run_seed)
        out = []
        for episode, seed in task.episodes:
            if stop.is_set():
                break
            result = run_episode(
                env, policy, episode_seed=seed, setting=setting, run_seed=task.run_seed, episode=episode, task=market
            )
            out.append(result)
            if on_episode is not None:
                with lock:
                    on_episode(result)
        return out

    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="episode")
    finished = False
    try:
        futures = [pool.submit(run_task, task) for task in tasks]
        done, _ = wait(futures, return_when=FIRST_EXCEPTION)
        for future in futures:  # the first error in protocol order among those that failed
            if future in done and future.exception() is not None:
                raise future.exception()  # type: ignore[misc]
        finished = True
        return [result for future in futures for result in future.result()]
    finally:
        stop.set()
        # On an error or a signal do not wait for the running episodes: the caller goes on to
        # stop the model server, which ends their pending calls at once.
        pool.shutdown(wait=finished, cancel_futures=True)
