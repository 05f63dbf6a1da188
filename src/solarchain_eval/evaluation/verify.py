"""Verify a run directory: its files against their sha256, then a sample of episodes re-run
(docs/comparing_results.md#verifying-a-run).

:func:`verify_run` checks every file of the run against the sha256 recorded in
``run_metadata.json`` (missing, extra and changed files, each named), checks that the recorded
protocol fingerprint agrees with the metadata and with its id, then re-runs ``episodes``
seeded-random episodes of every policy it can rebuild under the run's recorded protocol (dataset,
configuration, setting, episode-seed rule, Planner/Auditor options) and compares each re-run
episode's ``metrics.csv`` row, cell by cell, with the recorded one as the CSV writer writes it.

Before any re-run, ``metrics.csv`` must hold exactly the protocol's rollouts, each once, as many
as the metadata records (:func:`~.verify_checks.check_rollouts`, the leaderboard's rule too).
Policies are rebuilt from what the caller gives: built-ins by name, learned ones only from the
models the caller passes (``models``; a grid's units also from their own train units inside the
grid root), user agents only from specs the caller gives (``agents``, matched by name). The
run's metadata never decides what code runs or what file is loaded (docs/security.md). An agent that is not ``stateless`` (the
Random baseline draws from one generator across a run's episodes) has the episodes before each
chosen one replayed in order, as the run ran them (:func:`replay_plan`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..agents.base import Policy
from ..agents.build import build_agents
from ..agents.registry import known_policies
from ..agents.request import AgentContext, agent_requests
from ..agents.specs import AgentSpecError, parse_agent_spec
from ..common.errors import NamesOptions
from ..common.redaction import redact_text
from ..governance.errors import GovernanceConfigError
from ..governance.factory import AgenticOptions, Governance, LLMOptions
from ..llm.errors import LLMError
from ..protocol import EPISODE_SEED_RULES
from ..tasks.base import Task
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import DEFAULT_TASK
from .inflight import is_stateless
from .records import METRICS_FILE
from .reserved import check_reserved
from .rollout import begin_run, run_episode
from .run_metadata import RunMetadata, RunMetadataError
from .verify_checks import (
    Difference,
    VerifyError,
    check_checksums,
    check_protocol,
    first_difference,
    keeper_models,
    read_metadata,
    read_rollouts,
    resolve_dataset,
    run_task,
    written_row,
)
from .verify_plan import choose_episodes, default_seed, replay_plan

#: Episodes re-run per policy by default.
DEFAULT_VERIFY_EPISODES = 3
VERIFIED, DIFFERS, CANNOT_REBUILD = "verified", "differs", "cannot rebuild"


@dataclass(frozen=True)
class VerifyOptions:
    """What :func:`verify_run` re-runs and with what.

    Attributes
    ----------
    episodes : int
        Episodes re-run per policy (all of the run's when it has fewer).
    agents : sequence of str
        Agent specs (the grammar of ``--policies``) for the run's user agents, matched by name.
    agent_args : dict
        ``--agent-arg`` options for those agents, by agent name (None: every agent).
    llm_cache : Path, optional
        The record/replay cache the run's LLM calls are replayed from.
    seed : int, optional
        Seed of the episode choice (default: derived from the run's ``run_id``).
    data_dir : Path, optional
        A dataset directory to use instead of the recorded one; its CSVs must have the recorded sha256.
    grid_files : tuple of str
        Files a grid keeps in a unit beside the run's own (not vouched for, not extra).
    models : dict
        Trained models of the learned policies (``--models``: ``{name: PATH}`` or ``{"*": DIR}``).
    models_within : Path, optional
        A grid root: its units' recorded models inside it may be loaded too.
    """

    episodes: int = DEFAULT_VERIFY_EPISODES
    agents: Sequence[str] = ()
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    llm_cache: Path | None = None
    seed: int | None = None
    data_dir: Path | None = None
    grid_files: tuple[str, ...] = ()
    models: dict[str, Path] = field(default_factory=dict)
    models_within: Path | None = None


@dataclass(frozen=True)
class PolicyVerification:
    """The outcome for one policy: ``status`` is ``verified``, ``differs`` or ``cannot rebuild``.

    ``episodes`` counts the episodes compared, ``replayed`` the earlier episodes re-run only to
    bring a stateful agent to the state it had (not compared).
    """

    policy: str
    status: str
    episodes: int = 0
    replayed: int = 0
    difference: Difference | None = None
    reason: str = ""

    def line(self) -> str:
        if self.status == VERIFIED:
            replayed = f"; {self.replayed} earlier episode(s) replayed in order" if self.replayed else ""
            return f"{self.policy}: verified ({self.episodes} episode{'' if self.episodes == 1 else 's'}{replayed})"
        if self.status == DIFFERS:
            d = self.difference
            if d is None:
                return f"{self.policy}: differs: {self.reason}"
            return (
                f"{self.policy}: differs: episode {d.episode} of run seed {d.run_seed}, metric {d.metric}: "
                f"recorded {d.recorded}, re-run {d.rerun}"
            )
        return f"{self.policy}: cannot rebuild ({self.reason})"


@dataclass(frozen=True)
class RunVerification:
    """Everything :func:`verify_run` found about one run directory."""

    run_dir: Path
    checksum_problems: tuple[str, ...]
    protocol_id: str
    protocol_problems: tuple[str, ...]
    policies: tuple[PolicyVerification, ...]
    files_checked: int = 0
    rollout_problems: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Checksums, protocol and rollouts agree and no rebuilt policy differs."""
        problems = self.checksum_problems or self.protocol_problems or self.rollout_problems
        return not problems and all(p.status != DIFFERS for p in self.policies)

    def lines(self) -> list[str]:
        """One line per policy, one per problem, then the checksum result and protocol id (redacted:
        a recorded spec may carry credentials)."""
        out = [p.line() for p in self.policies]
        out += [f"rollouts: {problem}" for problem in self.rollout_problems]
        out += [f"checksum: {problem}" for problem in self.checksum_problems]
        out += [f"protocol: {problem}" for problem in self.protocol_problems]
        checksums = (
            f"checksums match ({self.files_checked} files)"
            if not self.checksum_problems
            else f"checksums FAIL ({len(self.checksum_problems)} problem(s))"
        )
        protocol = "" if not self.protocol_problems else " (inconsistent with the metadata)"
        out.append(f"{checksums}; protocol {self.protocol_id or '(none recorded)'}{protocol}")
        return [redact_text(line) for line in out]


@dataclass
class _Rerun:
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
    rerun: _Rerun,
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


def _builder(
    text: str,
    config: Any,
    models: dict[str, Path],
    options: VerifyOptions,
    stack: ExitStack,
    task: str = DEFAULT_TASK,
):
    """A function building the agent of spec ``text`` in ``task`` as the evaluation runner builds it."""
    # a submitted agent is re-run in its own process, where it cannot reach the env
    return _build_one(text, config, stack, task=task, models=models, agent_args=options.agent_args, isolate=True)


def _build_one(
    text: str, config: Any, stack: ExitStack, *, task: str = DEFAULT_TASK, **options: Any
) -> Callable[[], Policy]:
    """A function building the agent of spec ``text`` in ``task`` with the request ``options``, closed by ``stack``."""
    context = AgentContext(config, task)
    return lambda: build_agents(
        agent_requests([text], task=task, **options), context, stack=stack, check_name=check_reserved
    )[0]


def _recorded_builder(
    text: str,
    config: Any,
    models: dict[str, Path],
    options: VerifyOptions,
    stack: ExitStack,
    llm_agent: Mapping[str, Any] | None = None,
    task: Task | None = None,
) -> Callable[[], Policy] | str:
    """How to rebuild a policy from its recorded spec, or why it cannot be rebuilt."""
    if task is not None and task.name != DEFAULT_TASK and text in task.baselines():
        return _builder(text, config, models, options, stack, task.name)  # the installed task's own baseline
    if text.startswith("<"):
        return f"an agent object {text} passed from Python; pass its spec with --agent NAME=module:attr"
    try:
        parsed = parse_agent_spec(text, known_policies())
    except AgentSpecError as error:
        return f"recorded spec {text!r}: {error}; pass its spec with --agent"
    if parsed.kind == "builtin":
        return _builder(text, config, models, options, stack)
    if parsed.kind == "llm":
        if not llm_agent:
            return "the llm-agent's endpoint is not recorded in the run"
        if options.llm_cache is None:
            return "LLM calls; pass --llm-cache"
        return _build_one(text, config, stack, llm=LLMOptions.replaying(llm_agent, options.llm_cache))
    return f"a user agent ({text}); pass its spec with --agent to rebuild it"


def _given_builders(
    metadata: RunMetadata,
    config: Any,
    models: dict[str, Path],
    options: VerifyOptions,
    stack: ExitStack,
) -> dict[str, Callable[[], Policy]]:
    """The builders of the agents given with ``--agent``, by the name they build (checked before any work)."""
    names = metadata.policies
    given: dict[str, Callable[[], Policy]] = {}
    for text in options.agents:
        build = _builder(text, config, models, options, stack, metadata.task)
        try:
            name = build().name
        except (ValueError, OSError) as error:  # AgentSpecError, a model that cannot load, a missing file
            raise VerifyError.about("{opt_agents} {text}: {error}", text=text, error=error) from None
        if name not in names:
            raise VerifyError.about(
                "{opt_agents} {text} builds agent {name!r}; the run's policies are {names}",
                text=text,
                name=name,
                names=", ".join(names),
            )
        given[name] = build
    return given


def _agentic(metadata: RunMetadata, options: VerifyOptions) -> AgenticOptions | str | None:
    """The recorded Planner/Auditor options (None: not governed), or why they cannot be rebuilt."""
    record = metadata.agentic
    if record is None:
        return None
    if record.get("llm") is not None and options.llm_cache is None:
        return "LLM calls; pass --llm-cache"
    try:
        return AgenticOptions.from_record(record, llm_cache=options.llm_cache)
    except (GovernanceConfigError, LLMError, TypeError, ValueError) as error:
        return f"the recorded Planner/Auditor options: {error}"


def verify_run(run_dir: Path, options: VerifyOptions | None = None) -> RunVerification:
    """Check ``run_dir``'s files and protocol, then re-run a sample of its episodes (module docstring).

    Raises
    ------
    VerifyError
        No run directory or metadata, or options that cannot be used (a ``data_dir`` that is
        not the run's dataset, an ``agents`` spec that cannot be built or names no policy of the run).
    """
    options = options or VerifyOptions()
    if options.episodes < 1:
        raise VerifyError.about("{opt_episodes} must be at least 1, got {n}", n=options.episodes)
    run_dir = Path(run_dir)
    metadata = read_metadata(run_dir)
    task = run_task(metadata)  # an installed task, by the recorded name (before any check: one clear line)
    checksums = check_checksums(run_dir, metadata, options.grid_files)
    files_checked = len(metadata.files or {})
    names = metadata.policies
    try:
        config = metadata.task_config()
    except RunMetadataError as error:
        why = f"the recorded config is invalid: {error}"
        cannot = tuple(PolicyVerification(n, CANNOT_REBUILD, reason=why) for n in names)
        return RunVerification(run_dir, tuple(checksums), metadata.protocol_id or "", (why,), cannot, files_checked)
    protocol = check_protocol(metadata, config, task)
    recorded, rollouts = read_rollouts(run_dir, metadata, task)
    data_dir, no_data = resolve_dataset(metadata, options.data_dir, task)
    with ExitStack() as stack:
        models = keeper_models(metadata, options.models, options.models_within)
        given = _given_builders(metadata, config, models, options, stack)
        # A run whose rows are not its protocol's is not re-run: the rows would not say what was compared.
        results = (
            []
            if rollouts
            else _verify_policies(
                task, run_dir, metadata, config, data_dir, no_data, given, models, options, stack, recorded
            )
        )
    return RunVerification(
        run_dir,
        tuple(checksums),
        metadata.protocol_id or "",
        tuple(protocol),
        tuple(results),
        files_checked,
        tuple(rollouts),
    )


def _verify_policies(
    task: Task,
    run_dir: Path,
    metadata: RunMetadata,
    config: Any,
    data_dir: Path | None,
    no_data: str,
    given: dict[str, Callable[[], Policy]],
    models: dict[str, Path],
    options: VerifyOptions,
    stack: ExitStack,
    recorded: dict[tuple[str, int, int], dict[str, str]],
) -> list[PolicyVerification]:
    names, specs = metadata.policies, metadata.policy_specs
    protocol = metadata.protocol or {}
    rule = EPISODE_SEED_RULES.get(str(protocol.get("episode_seed_rule")))
    agentic = _agentic(metadata, options)
    metrics_path = run_dir / METRICS_FILE
    common = (
        no_data
        or (
            f"the episode-seed rule {protocol.get('episode_seed_rule')!r} is not one of this version's"
            if rule is None
            else ""
        )
        or (agentic if isinstance(agentic, str) else "")
        or ("" if metrics_path.is_file() else f"{metrics_path} is missing")
        or (
            "" if len(specs) == len(names) else "run_metadata.json lists policies and policy_specs of different lengths"
        )
    )
    if common:
        return [PolicyVerification(n, CANNOT_REBUILD, reason=common) for n in names]
    assert rule is not None and not isinstance(agentic, str)
    governance = (
        stack.enter_context(Governance(agentic, governance_view_of(task, config))) if agentic is not None else None
    )
    rerun = _Rerun(
        task=task,
        config=config,
        table=task.load_data(data_dir),  # None: a task without a dataset (resolve_dataset)
        setting=metadata.setting,
        run_seeds=metadata.run_seeds,
        episodes=metadata.episodes,
        episode_seeds=rule,
        governance=governance,
        recorded=recorded,
        # The runner drives one agent through every run seed, unless episodes ran in flight
        # (a private copy per run seed, :mod:`.inflight`).
        carry_over=metadata.concurrency <= 1,
    )
    seed = options.seed if options.seed is not None else default_seed(metadata.run_id)
    chosen = choose_episodes(rerun.run_seeds, rerun.episodes, options.episodes, seed)
    modes = protocol.get("action_modes") or {}
    results = []
    for name, text in zip(names, specs, strict=True):
        build = given.get(name) or _recorded_builder(text, config, models, options, stack, metadata.llm_agent, task)
        if isinstance(build, str):
            results.append(PolicyVerification(name, CANNOT_REBUILD, reason=build))
            continue
        try:
            base = build()
        except (ValueError, OSError) as error:  # a spec or model that cannot be built now
            why = error.message_for() if isinstance(error, NamesOptions) else str(error)
            results.append(PolicyVerification(name, CANNOT_REBUILD, reason=why))
            continue
        if modes.get(name, base.action_mode) != base.action_mode:
            why = f"action mode: recorded {modes[name]}, re-run {base.action_mode}"
            results.append(PolicyVerification(name, DIFFERS, reason=why))
            continue
        try:
            results.append(rerun_policy(name, base, build, chosen, rerun))
        except LLMError as error:  # a replayed call missing from the cache, for one
            results.append(PolicyVerification(name, CANNOT_REBUILD, reason=f"LLM replay: {error}"))
    return results
