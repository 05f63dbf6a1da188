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

from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..agents.base import Policy
from ..common.errors import NamesOptions
from ..governance.factory import Governance
from ..llm.errors import LLMError
from ..protocol import EPISODE_SEED_RULES
from ..tasks.base import Task
from ..tasks.governance_view import governance_view_of
from .records import METRICS_FILE
from .run_metadata import RunMetadata, RunMetadataError

# What verify finds, how it rebuilds and re-runs policies, and its checks live in verify_outcome,
# verify_rebuild, verify_replay, verify_checks and verify_plan; the `x as x` imports keep the names
# importable from here.
from .verify_checks import Difference as Difference
from .verify_checks import (
    VerifyError,
    check_checksums,
    check_protocol,
    keeper_models,
    read_metadata,
    read_rollouts,
    resolve_dataset,
    run_task,
)
from .verify_checks import first_difference as first_difference
from .verify_checks import written_row as written_row
from .verify_outcome import CANNOT_REBUILD, DIFFERS, PolicyVerification, RunVerification
from .verify_outcome import VERIFIED as VERIFIED
from .verify_plan import choose_episodes, default_seed
from .verify_plan import replay_plan as replay_plan
from .verify_rebuild import given_builders, recorded_agentic, recorded_builder
from .verify_replay import Rerun, rerun_policy

#: Episodes re-run per policy by default.
DEFAULT_VERIFY_EPISODES = 3


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
        given = given_builders(metadata, config, models, stack, agents=options.agents, agent_args=options.agent_args)
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
    agentic = recorded_agentic(metadata, options.llm_cache)
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
    rerun = Rerun(
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
        build = given.get(name) or recorded_builder(
            text,
            config,
            models,
            stack,
            agent_args=options.agent_args,
            llm_cache=options.llm_cache,
            llm_agent=metadata.llm_agent,
            task=task,
        )
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
