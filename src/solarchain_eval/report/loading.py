"""Read a run directory or a ``paper`` root into validated frames for the report.

The layout is the one :mod:`solarchain_eval.experiments.layout` defines; files are read one by
one (the same paths :func:`~solarchain_eval.experiments.layout.read_run_table` concatenates) so
that an error names the file, column and row at fault.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import pandas as pd

from ..common.redaction import redact_metadata
from ..evaluation.records import DIAGNOSTICS_FILE, SUMMARY_FILE
from ..evaluation.run_metadata import RunMetadata, RunMetadataError
from ..evaluation.rundir import verify_files, verify_run_dir
from ..experiments.layout import (
    ACTIONS_FILE,
    AGENTIC_LOG_FILE,
    CITY_HOUR_FILE,
    COMBINED_DIR,
    METADATA_FILE,
    METRICS_FILE,
    PAPER_METADATA_FILE,
    eval_unit_dirs,
    is_done,
    is_paper_root,
    run_table_paths,
)
from ..records_schema import EPISODE_KEYS
from ..tasks.base import Task, metric_names
from ..tasks.governance_view import GovernedTask, governance_view_of, harm_outcome_of
from ..tasks.registry import DEFAULT_TASK, UnknownTaskError, get_task
from .naming import SETTINGS
from .options import ReportDataError as ReportDataError
from .table_files import check_settings, read_json, read_tables

#: Keys of one agentic log step that the report reads (the agentic contract has more).
LOG_KEYS = (
    "policy",
    "setting",
    "run_seed",
    "episode",
    "episode_seed",
    "step",
    "absolute_hour",
    "hour",
    "raw_violation_rate",
    "supply_gap",
    "static_slippage",
    "kappa",
    "hard_trigger",
    "soft_trigger",
    "audited",
    "proposed_action",
    "final_action",
    "decision",
    "action_delta",
    "reason",
)
#: The ids every task's ``actions.csv`` holds (its step fields follow; the solar paper tables also read
#: the market's ``episode_start_hour``, which its step fields carry).
ACTION_KEYS = ("policy", "setting", "run_seed", "episode", "episode_seed", "step")
#: The columns every task's per-step extras table holds (the solar heat map also reads ``hour`` and
#: ``liquidity_ratio``, which the solar market's table carries).
CITY_HOUR_KEYS = ("policy", "setting", "run_seed", "episode", "step", "city", "city_reward")
#: Columns of ``governance_diagnostics.csv`` the audit-quality tables read.
DIAGNOSTICS_REQUIRED = (
    "policy",
    "setting",
    "run_seed",
    "episode",
    "start_hour",
    "step",
    "audited",
    "decision",
    "proposal_cost",
    "least_cost",
    "bounded_cost",
    "bounded_reward",
    "final_cost",
    "final_reward",
)


def _diagnostics_required(task: Task) -> tuple[str, ...]:
    """:data:`DIAGNOSTICS_REQUIRED` plus the task's harm outcome before and after the auditor (the
    governance tables' Δ column), so a file of other outcome names is refused naming the column."""
    if not isinstance(task, GovernedTask):
        return DIAGNOSTICS_REQUIRED
    harm = harm_outcome_of(governance_view_of(task))
    return (*DIAGNOSTICS_REQUIRED, f"bounded_{harm}", f"final_{harm}")


#: Rollout identity: one row per (setting, policy, run seed, episode).
ROLLOUT_KEY = ["setting", "policy", "run_seed", "episode"]


@dataclass
class ReportData:
    """Everything the report reads from one run directory or paper root.

    Attributes
    ----------
    metrics, actions, city_hour, logs
        One row per rollout, per step, per step and city, per agentic log step (frames may be
        empty when the run did not write that file). ``logs`` gains ``start_hour``.
    metadata
        ``paper_metadata.json`` (paper root) or ``run_metadata.json`` (run directory, as
        :class:`~solarchain_eval.evaluation.run_metadata.RunMetadata` reads it), or ``{}``, redacted.
    unit_metadata
        ``run_metadata.json`` of every evaluation unit of a paper root, by unit name (the same way).
    run_metadata, unit_run_metadata
        The run directory's record and the evaluation units' records, typed (absent files left out).
    sources
        The files read, by table name.
    unverified
        Why the files cannot be trusted as one run (see :func:`verify_report_inputs`); empty
        unless loaded with ``allow_unverified``.
    """

    root: Path
    kind: Literal["paper", "run"]
    metrics: pd.DataFrame
    actions: pd.DataFrame
    city_hour: pd.DataFrame
    logs: pd.DataFrame
    metadata: dict[str, Any] = field(default_factory=dict)
    unit_metadata: dict[str, dict[str, Any]] = field(default_factory=dict)
    run_metadata: RunMetadata | None = None
    unit_run_metadata: dict[str, RunMetadata] = field(default_factory=dict)
    sources: dict[str, list[Path]] = field(default_factory=dict)
    unverified: list[str] = field(default_factory=list)
    #: ``governance_diagnostics.csv`` rows (counterfactual step records; empty without them).
    diagnostics: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: The task the run evaluated (its ``run_metadata.json``'s, or its units'; ``solar`` when unrecorded).
    task: str = DEFAULT_TASK

    @property
    def task_spec(self) -> Task:
        """The :class:`~solarchain_eval.tasks.base.Task` called :attr:`task` (its metric declarations)."""
        return get_task(self.task)

    @property
    def settings(self) -> list[str]:
        """Settings with rollouts, in :data:`SETTINGS` order."""
        present = set(self.metrics["setting"])
        return [s for s in SETTINGS if s in present]

    def rollouts(self, setting: str) -> pd.DataFrame:
        """The metrics rows of one setting."""
        return self.metrics[self.metrics["setting"] == setting]


#: Per-row figures of the model calls a log row records (NaN where it records none): the
#: auditor's call at this step, and the planner's call on the episode's first row only (the plan,
#: with its call, is repeated on every row).
LLM_CALL_FIELDS = tuple(
    f"{kind}_{name}" for kind in ("planner", "auditor") for name in ("latency_s", "input_tokens", "output_tokens")
)


def _llm_call_fields(record: dict[str, Any]) -> dict[str, float]:
    out = dict.fromkeys(LLM_CALL_FIELDS, float("nan"))
    plan = record.get("plan")
    calls = {
        "auditor": record.get("llm"),
        "planner": plan.get("llm") if isinstance(plan, dict) and record.get("step") == 0 else None,
    }
    for kind, meta in calls.items():
        if isinstance(meta, dict):
            for name in ("latency_s", "input_tokens", "output_tokens"):
                value = meta.get(name)
                if isinstance(value, int | float) and not isinstance(value, bool):
                    out[f"{kind}_{name}"] = float(value)
    return out


def _flatten_log(record: dict[str, Any]) -> dict[str, Any]:
    row = {key: record[key] for key in LOG_KEYS}
    for key in ("proposed_action", "final_action"):
        row[key] = tuple(float(v) for v in record[key])
    row.update(_llm_call_fields(record))
    return row


def read_agentic_logs(path: Path) -> pd.DataFrame:
    """One row per logged agentic step of ``path`` (``agentic_logs.jsonl``), validated.

    Raises
    ------
    ReportDataError
        A line is not JSON, lacks a key the report reads, or has an action that is not 3 numbers.
    """
    rows = []
    with open(path, encoding="utf-8") as handle:
        for number, line in enumerate(handle, start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError as error:
                raise ReportDataError(f"{path}: line {number} is not JSON ({error.msg})") from None
            missing = [k for k in LOG_KEYS if k not in record]
            if missing:
                raise ReportDataError(f"{path}: line {number} lacks key(s) {', '.join(missing)}")
            for key in ("proposed_action", "final_action"):
                value = record[key]
                if not (isinstance(value, list) and len(value) == 3):
                    raise ReportDataError(f"{path}: line {number} field {key} is not a list of 3 numbers")
            rows.append(_flatten_log(record))
    frame = pd.DataFrame(rows, columns=[*LOG_KEYS, *LLM_CALL_FIELDS])
    if not frame.empty:
        check_settings(frame, path, "paper" if path.parent.parent.name == COMBINED_DIR else "run")
    return frame


def _redacted(metadata: dict[str, Any]) -> dict[str, Any]:
    """Metadata with its recorded command line and agent specs redacted (older runs recorded them verbatim)."""
    return redact_metadata(metadata) if isinstance(metadata, dict) else metadata


def _run_metadata(run_dir: Path) -> RunMetadata | None:
    """``run_dir``'s record (None when it has none: the checksums say so)."""
    path = run_dir / METADATA_FILE
    if not path.is_file():
        return None
    try:
        return RunMetadata.read(path)
    except RunMetadataError as error:
        raise ReportDataError(str(error)) from None


def _shown(record: RunMetadata | None) -> dict[str, Any]:
    return _redacted(record.to_dict()) if record is not None else {}


def verify_report_inputs(root: Path, kind: str) -> list[str]:
    """Why the files under ``root`` cannot be trusted as whole runs (empty when they can).

    A run directory is checked against the sha256 of every file recorded in its
    ``run_metadata.json``; a paper root checks each finished eval unit the same way and its
    combined files against ``paper_metadata.json``'s ``combined_sha256``.
    """
    if kind == "run":
        return verify_run_dir(root)
    problems = [p for unit in eval_unit_dirs(root) if is_done(unit) for p in verify_run_dir(unit)]
    return problems + verify_combined(root)


def verify_combined(root: Path) -> list[str]:
    """Problems of a paper root's combined files against ``paper_metadata.json``'s ``combined_sha256``."""
    meta_path = Path(root) / PAPER_METADATA_FILE
    recorded = read_json(meta_path).get("combined_sha256") or {}
    names = (METRICS_FILE, ACTIONS_FILE, CITY_HOUR_FILE, AGENTIC_LOG_FILE, DIAGNOSTICS_FILE, SUMMARY_FILE)
    problems = []
    for folder in sorted(p for p in (Path(root) / COMBINED_DIR).glob("*") if p.is_dir()):
        problems += verify_files(folder, recorded.get(folder.name), meta_path, names)
    return problems


def _task_of(root: Path, records: dict[Path, RunMetadata]) -> str:
    """The one task the records name (``solar`` without records), checked to be available.

    Raises
    ------
    ReportDataError
        Two records name different tasks, or the task is not available in this process.
    """
    tasks = {path: record.task for path, record in records.items()}
    names = sorted(set(tasks.values()))
    if len(names) > 1:
        first = next(p for p, t in tasks.items() if t == names[0])
        other = next(p for p, t in tasks.items() if t == names[1])
        raise ReportDataError(
            f"{first} records task {names[0]!r} but {other} records task {names[1]!r}; a report covers one task"
        )
    name = names[0] if names else DEFAULT_TASK
    try:
        get_task(name)
    except UnknownTaskError as error:
        where = next(iter(records), root)
        raise ReportDataError(f"{where}: {error}") from None
    return name


def _check_unique_rollouts(metrics: pd.DataFrame, paths: list[Path]) -> None:
    duplicated = metrics.duplicated(ROLLOUT_KEY, keep=False)
    if duplicated.any():
        row = metrics[duplicated].iloc[0]
        key = ", ".join(f"{k}={row[k]}" for k in ROLLOUT_KEY)
        raise ReportDataError(
            f"{', '.join(str(p) for p in paths)}: rollout ({key}) appears more than once; "
            "paired deltas need one row per setting, policy, run seed and episode"
        )


def load_report_data(root: Path, *, allow_unverified: bool = False) -> ReportData:
    """Read and validate the run directory or paper root ``root``.

    Parameters
    ----------
    root : Path
    allow_unverified : bool
        Load files that fail :func:`verify_report_inputs` anyway, listing the problems in
        ``ReportData.unverified`` (the report shows them as warnings).

    Raises
    ------
    ReportDataError
        ``root`` holds no metrics, a file is malformed (the message says which and where), or
        (without ``allow_unverified``) the files are not vouched for as whole runs.
    """
    root = Path(root)
    if not root.is_dir():
        raise ReportDataError(f"{root}: no such directory (expected a run directory or a paper root)")
    kind: Literal["paper", "run"] = "paper" if is_paper_root(root) else "run"
    run_metadata = _run_metadata(root) if kind == "run" else None
    units = {unit.name: _run_metadata(unit) for unit in eval_unit_dirs(root)} if kind == "paper" else {}
    records = {Path(r.where): r for r in [run_metadata, *units.values()] if r is not None}
    task = _task_of(root, records)
    # The metric columns are the task's declared ones (the solar market's for every run before tasks).
    task_spec = get_task(task)
    names = metric_names(task_spec)
    metrics, metric_paths = read_tables(root, METRICS_FILE, (*EPISODE_KEYS, *names), kind, names)
    if not metric_paths:
        where = f"{root}/{COMBINED_DIR}/<setting>/{METRICS_FILE}" if kind == "paper" else f"{root}/{METRICS_FILE}"
        raise ReportDataError(f"{root}: no {METRICS_FILE} found (looked for {where})")
    if metrics.empty:
        raise ReportDataError(f"{', '.join(str(p) for p in metric_paths)}: no rollouts (only a header)")
    _check_unique_rollouts(metrics, metric_paths)
    actions, action_paths = read_tables(root, ACTIONS_FILE, ACTION_KEYS, kind)
    city_hour, city_paths = read_tables(root, CITY_HOUR_FILE, CITY_HOUR_KEYS, kind)
    log_paths = run_table_paths(root, AGENTIC_LOG_FILE)
    logs = [read_agentic_logs(path) for path in log_paths]
    log_frame = pd.concat(logs, ignore_index=True) if logs else pd.DataFrame(columns=[*LOG_KEYS, *LLM_CALL_FIELDS])
    # Steps are consecutive hours, so the episode's start hour is absolute_hour - step.
    log_frame["start_hour"] = pd.to_numeric(log_frame["absolute_hour"]) - pd.to_numeric(log_frame["step"])
    diagnostics, diagnostic_paths = read_tables(root, DIAGNOSTICS_FILE, _diagnostics_required(task_spec), kind)
    # Checked after the files parse, so a malformed file gets the message naming its row.
    unverified = verify_report_inputs(root, kind)
    if unverified and not allow_unverified:
        more = f" (and {len(unverified) - 1} more problem(s))" if len(unverified) > 1 else ""
        raise ReportDataError.about(
            "{problem}{more}; refusing to report ({opt_allow_unverified} reports anyway, with warnings)",
            problem=unverified[0],
            more=more,
        )
    return ReportData(
        root=root,
        kind=kind,
        metrics=metrics,
        actions=actions,
        city_hour=city_hour,
        logs=log_frame,
        metadata=_redacted(read_json(root / PAPER_METADATA_FILE)) if kind == "paper" else _shown(run_metadata),
        unit_metadata={name: _shown(record) for name, record in units.items()},
        run_metadata=run_metadata,
        unit_run_metadata={name: record for name, record in units.items() if record is not None},
        sources={
            METRICS_FILE: metric_paths,
            ACTIONS_FILE: action_paths,
            CITY_HOUR_FILE: city_paths,
            AGENTIC_LOG_FILE: log_paths,
            DIAGNOSTICS_FILE: diagnostic_paths,
        },
        unverified=unverified,
        diagnostics=diagnostics,
        task=task,
    )
