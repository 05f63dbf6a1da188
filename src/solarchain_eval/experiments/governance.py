"""The governance leaderboard runs (docs/governance.md#leaderboard).

Every (planner, auditor) combination governs the same policies over the same run seeds and
episodes, in each asked setting, with counterfactual diagnostics on. Each combination is one run
directory (``runs/<setting>/<planner>--<auditor>/``, written by :func:`run_evaluation`), all of
them inside one leaderboard root published as a whole by :class:`~.rundir.RunDirWriter`. The
ranked tables and figures are the report layer's, so the caller hands their writer in
(``tables``; ``solarchain-eval governance`` passes the leaderboard of
:mod:`solarchain_eval.report.governance.leaderboard`); :func:`run_governance` then writes the
root's ``governance_metadata.json`` last, with the sha256 of what ``tables`` wrote, so a call from
Python leaves the root the command leaves.

``GovernanceSpec.task`` names the market governed (the solar market by default; any task whose
governance view :func:`~solarchain_eval.tasks.governance_view.governance_view_of` returns): each
run's files are that task's, its ``governance_diagnostics.csv`` columns its view's, and the root's
metadata names the task when it is not the solar market.

The ``random`` auditor matches the audits of a reference combination, episode by episode: the
``rule`` auditor of the same planner, scheduler controls and setting when it is asked for, else
the first other one.
"""

from __future__ import annotations

import dataclasses
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from ..common.atomic_files import atomic_write_json, sha256_file
from ..common.redaction import redact_command
from ..config import BenchmarkConfig
from ..evaluation.records import diagnostics_frame
from ..evaluation.rollout import EpisodeResult
from ..evaluation.run_spec import EvaluationSpec
from ..evaluation.runner import run_evaluation
from ..evaluation.settings import SETTING_AGENTIC, setting_has_physics_penalty
from ..governance.counterfactual import DEFAULT_UNSAFE_THRESHOLD
from ..governance.factory import AgenticOptions
from ..governance.wrapper import EXTRA_LOG_KEY
from ..protocol import PAPER_EPISODES, PAPER_SEED, PAPER_SEEDS
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import DEFAULT_TASK, get_task

RUNS_DIR = "runs"
#: What a leaderboard root was made with, written last (``complete``, the combinations, the sha256
#: of the tables).
GOVERNANCE_METADATA_FILE = "governance_metadata.json"


@dataclass(frozen=True)
class Combination:
    """One leaderboard entry: display labels and the layer's options."""

    planner_label: str
    auditor_label: str
    options: AgenticOptions

    @property
    def slug(self) -> str:
        name = f"{self.planner_label}--{self.auditor_label}"
        return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


@dataclass
class GovernanceSpec:
    """What the leaderboard evaluates (policies, seeds and episodes as for ``evaluate``).

    ``policies`` are agent specs as :class:`~solarchain_eval.evaluation.runner.EvaluationSpec`
    takes them (built-in names, ``package.module:attr``, ``path/file.py:attr``, ...), with their
    ``agent_args`` and ``vecnormalize``. ``task`` names the market (its ``config``: None, the
    task's default; for the solar market a :class:`~solarchain_eval.config.BenchmarkConfig`).

    Raises
    ------
    NoGovernanceViewError
        On construction, when ``task`` supplies no governance view (nothing has run).
    """

    policies: Sequence[str]
    combinations: Sequence[Combination]
    settings: Sequence[str] = (SETTING_AGENTIC,)
    run_seeds: Sequence[int] = PAPER_SEEDS
    episodes: int = PAPER_EPISODES
    data_dir: Path | None = None
    config: BenchmarkConfig | Any = None
    models: dict[str, Path] = field(default_factory=dict)
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    vecnormalize: dict[str | None, Path] = field(default_factory=dict)
    #: Run each user agent in a process of its own (``--isolate``; built-ins stay in this process).
    isolate: bool = False
    #: A step is unsafe when its proposal's avoidable cost exceeds this (the tables' label; recorded).
    unsafe_threshold: float = DEFAULT_UNSAFE_THRESHOLD
    #: The market governed, by name (:mod:`solarchain_eval.tasks`).
    task: str = DEFAULT_TASK

    def __post_init__(self) -> None:
        market = get_task(self.task)  # an unknown name: one line listing the installed tasks
        governance_view_of(market)  # a task without a governance view: one line, before any work
        if self.config is None:
            self.config = market.default_config()


@dataclass
class CombinationRun:
    """A finished combination in one setting."""

    combination: Combination
    setting: str
    run_dir: Path
    results: list[EpisodeResult]
    wall_s: float
    #: The policies' names (the ``policy`` column), in the spec's order.
    policies: list[str] = field(default_factory=list)
    #: The market governed (its governance view names the diagnostics' columns).
    task: str = DEFAULT_TASK


#: Writes a root's tables from its runs into the root; returns them by path relative to the root.
TablesWriter = Callable[[list[CombinationRun], Path], Mapping[str, Path]]


def audit_counts(results: Sequence[EpisodeResult]) -> dict[tuple[str, int, int], int]:
    """Audited steps per (policy, run seed, episode)."""
    return {
        (r.policy, int(r.run_seed), int(r.episode)): sum(1 for row in r.extras[EXTRA_LOG_KEY] if row["audited"])
        for r in results
    }


def _ordered(combinations: Sequence[Combination]) -> list[Combination]:
    """Random auditors last, so their reference has run; otherwise the order given."""
    return sorted(combinations, key=lambda c: c.options.auditor == "random")


def _reference(done: Sequence[CombinationRun], combination: Combination, setting: str) -> CombinationRun | None:
    candidates = [
        run
        for run in done
        if run.setting == setting
        and run.combination.options.planner == combination.options.planner
        and run.combination.options.controls == combination.options.controls
        and run.combination.options.auditor != "random"
    ]
    preferred = [run for run in candidates if run.combination.options.auditor == "rule"]
    return (preferred or candidates or [None])[0]


def run_governance(
    spec: GovernanceSpec,
    root: Path,
    *,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    on_combination: Callable[[Combination, str], None] | None = None,
    command: Sequence[str] | None = None,
    tables: TablesWriter | None = None,
) -> list[CombinationRun]:
    """Evaluate every combination in every setting into ``root/runs/<setting>/<slug>``, then let
    ``tables`` write the root's tables and write ``governance_metadata.json`` (see the module
    docstring). Without ``tables`` the metadata lists no files.
    """
    done: list[CombinationRun] = []
    for setting in spec.settings:
        for combination in _ordered(spec.combinations):
            options = dataclasses.replace(combination.options, diagnostics=True)
            if options.auditor == "random" and options.random_audit_rate is None:
                reference = _reference(done, combination, setting)
                if reference is not None:
                    options = dataclasses.replace(options, random_audit_counts=audit_counts(reference.results))
            if on_combination is not None:
                on_combination(combination, setting)
            evaluation = EvaluationSpec(
                policies=list(spec.policies),
                run_seeds=spec.run_seeds,
                episodes=spec.episodes,
                data_dir=spec.data_dir,
                no_physics_penalty=not setting_has_physics_penalty(setting),
                config=spec.config,
                models=spec.models,
                agentic=options,
                agent_args=spec.agent_args,
                vecnormalize=spec.vecnormalize,
                isolate=spec.isolate,
                task=spec.task,
            )
            run_dir = Path(root) / RUNS_DIR / setting / combination.slug
            outcome = run_evaluation(evaluation, run_dir, on_episode=on_episode, command=command)
            used = dataclasses.replace(combination, options=options)
            names = list(outcome.access)  # every policy's name, in the spec's order
            done.append(CombinationRun(used, setting, run_dir, outcome.results, outcome.wall_s, names, spec.task))
    files = dict(tables(done, Path(root))) if tables is not None else {}
    atomic_write_json(Path(root) / GOVERNANCE_METADATA_FILE, governance_metadata(spec, done, files, command))
    return done


def governance_metadata(
    spec: GovernanceSpec,
    runs: Sequence[CombinationRun],
    files: Mapping[str, Path],
    command: Sequence[str] | None = None,
) -> dict[str, Any]:
    """What ``governance_metadata.json`` holds: the command (credentials redacted), the unsafe
    threshold, each run's combination with its options, the settings, the policies' names and
    the sha256 of ``files`` (paths relative to the root); and ``task`` when the market is not the
    solar market (a solar root's file is the one before tasks)."""
    named = {} if spec.task == DEFAULT_TASK else {"task": spec.task}
    metadata = {
        "complete": True,
        **named,
        "command": redact_command(command if command is not None else sys.argv),
        "unsafe_threshold": spec.unsafe_threshold,
        "combinations": [
            {"planner": c.planner_label, "auditor": c.auditor_label, "options": c.options.describe()}
            for c in (run.combination for run in runs)
        ],
        "settings": list(spec.settings),
        "policies": runs[0].policies if runs else [],
        "files": {name: sha256_file(path) for name, path in sorted(files.items())},
    }
    return json.loads(json.dumps(metadata, default=str))  # options' paths and enums as text


def leaderboard_frames(runs: Sequence[CombinationRun]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(diagnostics of every run with display labels, in the columns of each run's task, LLM usage
    per combination and setting)."""
    frames, usage = [], []
    for run in runs:
        frame = diagnostics_frame(run.results, get_task(run.task))
        if frame is None:
            continue
        frames.append(frame.assign(planner=run.combination.planner_label, auditor=run.combination.auditor_label))
        calls = tokens = 0
        latency = 0.0
        for r in run.results:
            for row in r.extras.get(EXTRA_LOG_KEY, ()):
                meta = row.get("llm")
                if meta:
                    calls += 1
                    tokens += int(meta.get("input_tokens") or 0) + int(meta.get("output_tokens") or 0)
                    latency += float(meta.get("latency_s") or 0.0)
        usage.append(
            {
                "planner": run.combination.planner_label,
                "auditor": run.combination.auditor_label,
                "setting": run.setting,
                "llm_calls": calls,
                "llm_tokens": tokens,
                "llm_mean_latency_s": latency / calls if calls else 0.0,
                "wall_s": run.wall_s,
            }
        )
    diagnostics = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    return diagnostics, pd.DataFrame(usage)


@dataclass(frozen=True)
class Overhead:
    """Wall-clock seconds of the same agentic evaluation without and with diagnostics."""

    without_s: list[float]
    with_s: list[float]

    @property
    def ratio(self) -> float:
        """Median with / median without."""
        return float(statistics.median(self.with_s) / statistics.median(self.without_s))


def diagnostics_overhead(
    data_dir: Path | None,
    *,
    policies: Sequence[str] = ("static", "random", "myopic"),
    run_seeds: Sequence[int] = (PAPER_SEED,),
    episodes: int = 30,
    repeats: int = 3,
    options: AgenticOptions | None = None,
    task: str = DEFAULT_TASK,
) -> Overhead:
    """Time ``evaluate`` of ``task`` (files included) behind the layer, with and without
    diagnostics, alternating the two so drifts of a shared machine hit both alike (``data_dir``
    None: the task's default dataset)."""
    base = options if options is not None else AgenticOptions()
    times: dict[bool, list[float]] = {False: [], True: []}
    with tempfile.TemporaryDirectory(prefix="solarchain-bench-diagnostics-") as tmp:
        for repeat in range(repeats):
            for diagnostics in (False, True):
                spec = EvaluationSpec(
                    policies=list(policies),
                    run_seeds=run_seeds,
                    episodes=episodes,
                    data_dir=None if data_dir is None else Path(data_dir),
                    agentic=dataclasses.replace(base, diagnostics=diagnostics),
                    task=task,
                )
                started = time.perf_counter()
                run_evaluation(spec, Path(tmp) / f"{repeat}-{int(diagnostics)}", command=["bench"])
                times[diagnostics].append(time.perf_counter() - started)
    return Overhead(times[False], times[True])
