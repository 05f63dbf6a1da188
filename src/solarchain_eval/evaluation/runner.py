"""The ``evaluate`` stage: policies × run seeds × episodes -> a run directory.

Inputs and the run directory are validated (dataset, policy names, config, ``--out``) before
any work; the files are staged beside the run directory, ``run_metadata.json`` (with the sha256
of every other file) last, and the whole directory is published by a rename
(:class:`~.rundir.RunDirWriter`, see docs/output_safety.md).
"""

from __future__ import annotations

import copy
import sys
import time
import uuid
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..agents.adapters import AgentFailure, UserAgent
from ..agents.base import Policy, access_label
from ..agents.build import build_agents
from ..agents.isolated import IsolatedAgent
from ..agents.request import AgentContext, AgentRequest, agent_requests
from ..common.atomic_files import sha256_file
from ..common.redaction import redact_command, redact_spec
from ..common.versions import git_commit, package_versions
from ..governance.factory import AgenticOptions, Governance, LLMOptions
from ..protocol import PAPER_EPISODES, PAPER_SEEDS, episode_seed_rule_name, paper_episode_seeds
from ..records_schema import RECORDS_SCHEMA_VERSION
from ..tasks.base import Task
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import DEFAULT_TASK, get_task
from .fingerprint import protocol_fingerprint, protocol_id
from .inflight import run_in_flight
from .record_stream import RecordStream, check_disk_space
from .records import METADATA_FILE
from .reserved import check_reserved
from .rollout import EpisodeResult, begin_run, run_policy
from .run_metadata import RunMetadata
from .rundir import RunDirWriter, kill_point
from .setting_resolution import resolve_setting
from .settings import Setting


@dataclass
class EvaluationSpec:
    """What to evaluate.

    ``policies`` are agent specs (built-in names such as ``"static"``, ``"pkg.module:attr"``,
    ``"NAME=http://..."``: :mod:`solarchain_eval.agents.specs`) or agents (objects with ``act``,
    functions ``observation -> action``, Stable-Baselines3 models). Their names must be unique.
    ``task`` names the market (:func:`~solarchain_eval.tasks.registry.get_task`); ``config`` is that
    task's configuration (None: its default, for the solar market ``BenchmarkConfig()``), and a
    task other than the solar market offers its own baselines by name (``Task.baselines``).

    ``setting`` (a :class:`~solarchain_eval.evaluation.settings.Setting` or a registered name)
    fixes the reward, the governance and the config overrides; once built, ``setting`` is its
    name, and ``no_physics_penalty`` and ``agentic`` are what it runs with. Without it, as
    before: with ``agentic`` set, every policy is wrapped by the Planner/Auditor layer and the
    setting is ``llm`` (``llm_no_physics`` with ``no_physics_penalty``); ``setting_label`` names a
    registered setting whose reward and governance must agree with those two.
    (:func:`~solarchain_eval.evaluation.setting_resolution.resolve_setting` reconciles them.)
    """

    policies: Sequence[str | Policy]
    run_seeds: Sequence[int] = PAPER_SEEDS
    episodes: int = PAPER_EPISODES
    data_dir: Path | None = None
    #: The reward switch (None: the setting's; False without a setting).
    no_physics_penalty: bool | None = None
    #: The task's configuration (None: ``get_task(task).default_config()``, set on construction).
    config: Any = None
    models: dict[str, Path] = field(default_factory=dict)
    episode_seeds: Callable[[int, int], list[int]] = paper_episode_seeds
    agentic: AgenticOptions | None = None
    #: Episodes in flight (threads; see :mod:`.inflight`). The results do not depend on it.
    concurrency: int = 1
    #: A registered setting's name for the records (None: the paper's setting of this reward and governance).
    setting_label: str | None = None
    #: ``--agent-arg`` options for agents built from classes and factories, by agent name (None: all).
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    #: VecNormalize statistics for ``sb3:`` agents, by agent name (None: the only one).
    vecnormalize: dict[str | None, Path] = field(default_factory=dict)
    #: The endpoint of the ``llm-agent`` baseline (needed when it is among the policies).
    llm: LLMOptions | None = None
    #: Run user agents (Python objects, ``module:attr``, ``file.py:attr``, plugins, ``sb3:``) each in a
    #: process of its own (:mod:`~solarchain_eval.agents.isolated`); built-ins stay in this process.
    isolate: bool = False
    #: The market evaluated, by name (:mod:`solarchain_eval.tasks`).
    task: str = DEFAULT_TASK
    #: The setting (a Setting or a registered name); its name once the spec is built.
    setting: Setting | str | None = None
    _setting: Setting = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.config is None:  # an unknown task name is refused here, before any work
            self.config = get_task(self.task).default_config()
        self._setting, self.agentic = resolve_setting(
            self.setting, label=self.setting_label, no_physics_penalty=self.no_physics_penalty, agentic=self.agentic
        )
        self.setting = self._setting.name
        self.no_physics_penalty = self._setting.no_physics_penalty

    @property
    def setting_spec(self) -> Setting:
        """The resolved :class:`~solarchain_eval.evaluation.settings.Setting`."""
        return self._setting

    def run_config(self) -> Any:
        """The config the evaluation runs: ``config`` with the setting's reward switch and overrides."""
        return self._setting.apply(self.config, get_task(self.task))


@dataclass
class EvaluationOutcome:
    """A published run: its directory, episodes, files, wall time and protocol."""

    run_dir: Path
    results: list[EpisodeResult]
    files: dict[str, Path]
    wall_s: float
    #: The protocol fingerprint (:mod:`.fingerprint`) and its short id.
    protocol: dict[str, Any] = field(default_factory=dict)
    protocol_id: str = ""
    #: Policy name -> "isolated", "in-process" or "privileged" (:func:`~solarchain_eval.agents.base.access_label`).
    access: dict[str, str] = field(default_factory=dict)
    #: What ``summary.json`` holds, and the number of episodes run (also when ``results`` was not kept).
    summary: list[dict[str, Any]] = field(default_factory=list)
    episodes: int = 0


def dataset_provenance(data: Any) -> dict[str, Any]:
    """Where the solar market's dataset ``data`` came from (``Task.provenance`` of the default task)."""
    return get_task().provenance(data)


def resolved_config(spec: EvaluationSpec) -> Any:
    """The spec's task configuration with its setting's reward switch and config overrides applied."""
    return spec.run_config()


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


def run_evaluation(
    spec: EvaluationSpec,
    run_dir: Path,
    *,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    command: Sequence[str] | None = None,
    overwrite: bool = False,
    keep: Sequence[str] = (),
    keep_results: bool = True,
    step_format: str = "csv",
) -> EvaluationOutcome:
    """Evaluate ``spec`` and publish the run directory ``run_dir`` as a whole.

    Parameters
    ----------
    spec : EvaluationSpec
    run_dir : Path
        Must be absent or empty unless ``overwrite``; refused (``RunDirError``) before any work
        if it is a file, unwritable, holds anything, or is being written by another live run.
    on_episode : callable, optional
        Called with each finished episode (progress bars).
    command : sequence of str, optional
        The command line to record (redacted of credentials); default ``sys.argv``.
    overwrite : bool
        Replace an existing run directory (its old files are removed, never mixed in).
    keep : sequence of str
        File names in ``run_dir`` owned by the caller (a grid unit's ``unit.json``), carried over.
    keep_results : bool
        Return every episode's steps in ``results``; without it each episode is dropped once its
        records are written, so memory stays flat in the number of episodes (``evaluate``).
    step_format : str
        ``"csv"`` (``actions.csv``, ``city_hour_policy.csv``) or ``"parquet"`` (``actions.parquet``,
        ``city_hour_policy.parquet``).

    Raises
    ------
    RunDirError
        Also when the records would not fit on the disk (the estimate is in the message).
    """
    started = time.perf_counter()
    started_at = datetime.now(UTC).isoformat(timespec="seconds")
    config = resolved_config(spec)
    task = get_task(spec.task)
    table = task.load_data(task.data_dir(spec.data_dir, config))  # validates before anything is written
    extras = task.step_extra_names(table)
    setting = spec.setting
    episodes = len(spec.policies) * len(spec.run_seeds) * spec.episodes
    check_disk_space(run_dir, episodes, task.episode_steps(config), len(extras), step_format)

    with ExitStack() as stack:
        policies = make_policies(spec, stack)
        writer = stack.enter_context(RunDirWriter(run_dir, overwrite=overwrite, keep=keep))
        governance = (
            stack.enter_context(Governance(spec.agentic, governance_view_of(task, config)))
            if spec.agentic is not None
            else None
        )
        assert writer.staging is not None
        stream = stack.enter_context(RecordStream(writer.staging, extras, step_format, task))
        results: list[EpisodeResult] = []

        def record(result: EpisodeResult) -> None:
            stream.add(result)
            if keep_results:
                results.append(result)

        if spec.concurrency > 1:
            finished = run_in_flight(
                policies,
                lambda mode: task.make_env(config, table, action_mode=mode),
                setting=setting,
                run_seeds=spec.run_seeds,
                episodes=spec.episodes,
                episode_seeds=spec.episode_seeds,
                workers=spec.concurrency,
                wrap=governance.wrap if governance is not None else None,
                on_episode=on_episode,
                market=task,
            )
            for result in finished:  # in protocol order; few episodes (they wait on a model)
                record(result)
        else:
            wrapped = [governance.wrap(p) for p in policies] if governance is not None else policies
            _run_sequentially(task, wrapped, spec, config, table, setting, on_episode, record)
        files = stream.finish()
        kill_point("staged")
        wall_s = time.perf_counter() - started
        rows = {"metrics": stream.episodes, "actions": stream.steps}
        metadata = _metadata(task, spec, config, table, policies, rows, files, command, started_at, wall_s, setting)
        metadata.write(writer.staging / METADATA_FILE)
        writer.publish()
    files = {name: Path(run_dir) / name for name in [*files, METADATA_FILE]}
    return EvaluationOutcome(
        run_dir=run_dir,
        results=results,
        files=files,
        wall_s=wall_s,
        protocol=metadata.fingerprint(),
        protocol_id=str(metadata.protocol_id),
        access=metadata.policy_access,
        summary=stream.summary,
        episodes=stream.episodes,
    )


def _run_sequentially(
    task: Task,
    policies: Sequence[Policy],
    spec: EvaluationSpec,
    config: Any,
    table: Any,
    setting: str,
    on_episode: Callable[[EpisodeResult], None] | None,
    record: Callable[[EpisodeResult], None],
) -> None:
    """Every policy's runs and episodes in protocol order, one env per action mode, each
    episode handed to ``record`` as it finishes."""
    envs: dict[str, Any] = {}
    for policy in policies:
        env = envs.get(policy.action_mode)
        if env is None:
            env = envs[policy.action_mode] = task.make_env(config, table, action_mode=policy.action_mode)
        for result in run_policy(
            env,
            policy,
            setting=setting,
            run_seeds=spec.run_seeds,
            episodes=spec.episodes,
            episode_seeds=spec.episode_seeds,
            on_episode=on_episode,
            task=task,
        ):
            record(result)


def _metadata(
    task: Task,
    spec: EvaluationSpec,
    config: Any,
    table: Any,
    policies: Sequence[Policy],
    rows: dict[str, int],
    files: dict[str, Path],
    command: Sequence[str] | None,
    started_at: str,
    wall_s: float,
    setting: str,
) -> RunMetadata:
    dataset = task.provenance(table)
    governed = spec.agentic is not None
    protocol = protocol_fingerprint(
        dataset_sha256=dataset["files"],
        run_seeds=spec.run_seeds,
        episodes=spec.episodes,
        episode_seed_rule=episode_seed_rule_name(spec.episode_seeds),
        setting=setting,
        config=config,
        action_modes={p.name: p.action_mode for p in policies},
        task=task,
    )
    # ``task`` only when it is not the solar market: a solar run's file is the one before tasks
    named = {} if task.name == DEFAULT_TASK else {"task": task.name}
    return RunMetadata(
        **named,
        complete=True,
        run_id=uuid.uuid4().hex,
        # sha256 of every file this metadata vouches for; ``report`` verifies them.
        files={name: sha256_file(path) for name, path in sorted(files.items())},
        command=redact_command(command if command is not None else sys.argv),
        started_at=started_at,
        wall_s=round(wall_s, 3),
        git_commit=git_commit(),
        package_versions=package_versions(),
        setting=setting,
        records_schema_version=RECORDS_SCHEMA_VERSION,
        policies=[p.name for p in policies],
        policy_specs=[redact_spec(p) if isinstance(p, str) else f"<{type(p).__name__}>" for p in spec.policies],
        # Behind the Planner/Auditor layer every row is privileged: the layer reads hours ahead.
        policy_access={p.name: "privileged" if governed else access_label(p) for p in policies},
        protocol=protocol,
        protocol_id=protocol_id(protocol),
        agentic=spec.agentic.describe() if spec.agentic is not None else None,
        # the llm-agent's endpoint and cache (what replays it), when it is among the policies
        llm_agent=spec.llm.describe() if spec.llm is not None else None,
        concurrency=int(spec.concurrency),
        run_seeds=[int(s) for s in spec.run_seeds],
        episodes=int(spec.episodes),
        episode_seed_protocol=getattr(spec.episode_seeds, "__name__", "custom"),
        rows=rows,
        dataset=dataset,
        models={k: str(v) for k, v in spec.models.items()},
        config=task.config_record(config),
    )
