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
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from ..agents.base import Policy
from ..agents.registry import make_policy
from ..common.atomic_files import atomic_write_json, sha256_file
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..config import BenchmarkConfig
from ..data.default import resolve_data_dir
from ..data.provenance import dataset_provenance as dataset_provenance  # re-exported
from ..data.table import HourlyTable, load_table
from ..envs.env import SolarChainEnv
from ..governance.factory import AgenticOptions, Governance
from ..protocol import PAPER_EPISODES, PAPER_SEEDS, paper_episode_seeds
from ..records_schema import RECORDS_SCHEMA_VERSION
from .inflight import run_in_flight
from .records import METADATA_FILE, write_records
from .rollout import EpisodeResult, run_policy
from .rundir import RunDirWriter, kill_point
from .settings import KNOWN_SETTINGS, setting_name


@dataclass
class EvaluationSpec:
    """What to evaluate.

    ``policies`` are names (built with ``make_policy``) or ready :class:`Policy` objects.
    With ``agentic`` set, every policy is wrapped by the Planner/Auditor layer and the
    setting is ``llm`` (``llm_no_physics`` with ``no_physics_penalty``). ``setting_label`` names a
    setting added with :func:`~solarchain_eval.evaluation.settings.register_setting` instead; its
    reward and governance must agree with ``no_physics_penalty`` and ``agentic``.
    """

    policies: Sequence[str | Policy]
    run_seeds: Sequence[int] = PAPER_SEEDS
    episodes: int = PAPER_EPISODES
    data_dir: Path | None = None
    no_physics_penalty: bool = False
    config: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    models: dict[str, Path] = field(default_factory=dict)
    episode_seeds: Callable[[int, int], list[int]] = paper_episode_seeds
    agentic: AgenticOptions | None = None
    #: Episodes in flight (threads; see :mod:`.inflight`). The results do not depend on it.
    concurrency: int = 1
    #: A registered setting's name for the records (None: the paper's setting of this reward and governance).
    setting_label: str | None = None

    def __post_init__(self) -> None:
        if self.setting_label is None:
            return
        known = KNOWN_SETTINGS.get(self.setting_label)
        if known is None:
            raise ValueError(f"unknown setting {self.setting_label!r} (registered: {', '.join(KNOWN_SETTINGS)})")
        if (known.no_physics_penalty, known.agentic) != (self.no_physics_penalty, self.agentic is not None):
            raise ValueError(
                f"setting {self.setting_label!r} has no_physics_penalty={known.no_physics_penalty} and "
                f"agentic={known.agentic}; the evaluation asks for {self.no_physics_penalty} and {self.agentic is not None}"
            )

    @property
    def setting(self) -> str:
        if self.setting_label is not None:
            return self.setting_label
        return setting_name(agentic=self.agentic is not None, no_physics_penalty=self.no_physics_penalty)


@dataclass
class EvaluationOutcome:
    run_dir: Path
    results: list[EpisodeResult]
    files: dict[str, Path]
    wall_s: float


def make_policies(spec: EvaluationSpec) -> list[Policy]:
    """The spec's policies, built: names through ``make_policy`` with the spec's config (its reward
    setting applied) and models, ready policies as they are.

    Raises
    ------
    ValueError
        An unknown policy name or a model that cannot be loaded.
    FileNotFoundError
        A learned policy without a trained model (the message lists where it looked).
    """
    config = spec.config.with_updates(no_physics_penalty=spec.no_physics_penalty)
    return [p if not isinstance(p, str) else make_policy(p, config, spec.models) for p in spec.policies]


def run_evaluation(
    spec: EvaluationSpec,
    run_dir: Path,
    *,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    command: Sequence[str] | None = None,
    overwrite: bool = False,
    keep: Sequence[str] = (),
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
    """
    started = time.perf_counter()
    started_at = datetime.now(UTC).isoformat(timespec="seconds")
    config = spec.config.with_updates(no_physics_penalty=spec.no_physics_penalty)
    data_dir = resolve_data_dir(spec.data_dir, config.data_dir)
    table = load_table(data_dir)  # validates before anything is written
    policies = make_policies(spec)
    setting = spec.setting

    with ExitStack() as stack:
        writer = stack.enter_context(RunDirWriter(run_dir, overwrite=overwrite, keep=keep))
        governance = stack.enter_context(Governance(spec.agentic, config.market)) if spec.agentic is not None else None
        if spec.concurrency > 1:
            results = run_in_flight(
                policies,
                lambda mode: SolarChainEnv(config=config, table=table, action_mode=mode),
                setting=setting,
                run_seeds=spec.run_seeds,
                episodes=spec.episodes,
                episode_seeds=spec.episode_seeds,
                workers=spec.concurrency,
                wrap=governance.wrap if governance is not None else None,
                on_episode=on_episode,
            )
        else:
            wrapped = [governance.wrap(p) for p in policies] if governance is not None else policies
            results = _run_sequentially(wrapped, spec, config, table, setting, on_episode)
        assert writer.staging is not None
        files = write_records(writer.staging, results, table.cities)
        kill_point("staged")
        wall_s = time.perf_counter() - started
        metadata = _metadata(spec, config, table, results, files, command, started_at, wall_s, setting)
        atomic_write_json(writer.staging / METADATA_FILE, metadata)
        writer.publish()
    files = {name: Path(run_dir) / name for name in [*files, METADATA_FILE]}
    return EvaluationOutcome(run_dir=run_dir, results=results, files=files, wall_s=wall_s)


def _run_sequentially(
    policies: Sequence[Policy],
    spec: EvaluationSpec,
    config: BenchmarkConfig,
    table: HourlyTable,
    setting: str,
    on_episode: Callable[[EpisodeResult], None] | None,
) -> list[EpisodeResult]:
    """Every policy's runs and episodes in protocol order, one env per action mode."""
    envs: dict[str, SolarChainEnv] = {}
    results: list[EpisodeResult] = []
    for policy in policies:
        env = envs.get(policy.action_mode)
        if env is None:
            env = envs[policy.action_mode] = SolarChainEnv(config=config, table=table, action_mode=policy.action_mode)
        results.extend(
            run_policy(
                env,
                policy,
                setting=setting,
                run_seeds=spec.run_seeds,
                episodes=spec.episodes,
                episode_seeds=spec.episode_seeds,
                on_episode=on_episode,
            )
        )
    return results


def _metadata(
    spec: EvaluationSpec,
    config: BenchmarkConfig,
    table: HourlyTable,
    results: list[EpisodeResult],
    files: dict[str, Path],
    command: Sequence[str] | None,
    started_at: str,
    wall_s: float,
    setting: str,
) -> dict:
    return {
        "complete": True,
        "run_id": uuid.uuid4().hex,
        # sha256 of every file this metadata vouches for; ``report`` verifies them.
        "files": {name: sha256_file(path) for name, path in sorted(files.items())},
        "command": redact_command(command if command is not None else sys.argv),
        "started_at": started_at,
        "wall_s": round(wall_s, 3),
        "git_commit": git_commit(),
        "package_versions": package_versions(),
        "setting": setting,
        "records_schema_version": RECORDS_SCHEMA_VERSION,
        "policies": [p if isinstance(p, str) else p.name for p in spec.policies],
        "agentic": spec.agentic.describe() if spec.agentic is not None else None,
        "concurrency": int(spec.concurrency),
        "run_seeds": [int(s) for s in spec.run_seeds],
        "episodes": int(spec.episodes),
        "episode_seed_protocol": getattr(spec.episode_seeds, "__name__", "custom"),
        "rows": {"metrics": len(results), "actions": sum(r.n_steps for r in results)},
        "dataset": dataset_provenance(table),
        "models": {k: str(v) for k, v in spec.models.items()},
        "config": config.model_dump(),
    }
