"""The ``evaluate`` stage: policies × run seeds × episodes -> a run directory.

Inputs and the run directory are validated (dataset, policy names, config, ``--out``) before
any work; the files are staged beside the run directory, ``run_metadata.json`` (with the sha256
of every other file) last, and the whole directory is published by a rename
(:class:`~.rundir.RunDirWriter`, see docs/output_safety.md).
"""

from __future__ import annotations

import sys
import time
import uuid
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..agents.base import Policy, access_label
from ..common.atomic_files import sha256_file
from ..common.redaction import redact_command, redact_spec
from ..common.versions import git_commit, package_versions
from ..governance.factory import Governance
from ..protocol import episode_seed_rule_name
from ..records_schema import RECORDS_SCHEMA_VERSION
from ..tasks.base import Task
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import DEFAULT_TASK, get_task

# The spec and the agents' setup live in run_spec and agent_setup; the `x as x` imports keep their
# names importable from here.
from .agent_setup import agent_requests_of as agent_requests_of
from .agent_setup import check_agent_requests as check_agent_requests
from .agent_setup import check_agents as check_agents
from .agent_setup import make_policies
from .fingerprint import protocol_fingerprint, protocol_id
from .inflight import run_in_flight
from .record_stream import RecordStream, check_disk_space
from .records import METADATA_FILE
from .rollout import EpisodeResult, run_policy
from .run_metadata import RunMetadata
from .run_spec import EvaluationOutcome, EvaluationSpec, resolved_config
from .run_spec import dataset_provenance as dataset_provenance
from .rundir import RunDirWriter, kill_point


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
