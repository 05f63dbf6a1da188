"""What one leaderboard input holds: its sections, one per setting, with the protocol their rows
were evaluated under.

A run directory is one section (its setting); a paper root is one section per setting, whose
protocol merges its evaluation units' (each unit evaluates one run seed: the section's run seeds
are theirs together). Every input is read and verified by
:func:`~solarchain_eval.report.loading.load_report_data` (every file against its recorded
sha256). Every policy must hold exactly the rollouts its protocol promises (run seeds × episodes,
each once: :func:`~solarchain_eval.evaluation.verify_checks.rollout_set_problem`, verify's rule),
so that rows of different inputs pair up episode by episode.

The rule of one board (docs/comparing_results.md): all sections must be of one task and share
the protocol *without its setting* (:func:`board_fingerprint`: the setting and the reward switch it
implies are left out; :mod:`.grouping` checks it); rows are ranked per setting.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from ...common.errors import InputDataError, NamesOptions
from ...config import BenchmarkConfig
from ...evaluation.fingerprint import protocol_id, task_config_sha256

# The legacy names live with the run record's model now (LEGACY_*, UNKNOWN_ACCESS, rule_name: kept importable here).
from ...evaluation.run_metadata import LEGACY_ACCESS as LEGACY_ACCESS
from ...evaluation.run_metadata import LEGACY_ENV_ID as LEGACY_ENV_ID
from ...evaluation.run_metadata import LEGACY_PROTOCOL_KEYS as LEGACY_PROTOCOL_KEYS
from ...evaluation.run_metadata import UNKNOWN_ACCESS as UNKNOWN_ACCESS
from ...evaluation.run_metadata import ProtocolMismatch, RunMetadata, RunMetadataError, setting_protocol
from ...evaluation.run_metadata import rule_name as rule_name
from ...evaluation.verify_checks import rollout_set_problem
from ...experiments.layout import METADATA_FILE, UNITS_DIR, is_done
from ...tasks.registry import DEFAULT_TASK, get_task
from ..loading import ReportData, load_report_data


class LeaderboardError(NamesOptions, InputDataError, ValueError):
    """The inputs cannot be ranked on one board (the one-line message names the inputs and why)."""


@dataclass
class Section:
    """The rows of one setting of one input, with their protocol.

    Attributes
    ----------
    source : str
        The input as the user named it (a path, or a tarball's path).
    where : str
        The source with the setting (``RUN [main]``), as refusals name it.
    setting : str
    protocol : dict
        The setting's protocol fingerprint (:func:`~solarchain_eval.evaluation.fingerprint.protocol_fingerprint`).
    board_protocol : dict
        :func:`board_fingerprint` of it: what every section of one board shares.
    metrics : pandas.DataFrame
        The setting's ``metrics.csv`` rows.
    access : dict
        Policy -> ``"isolated"``, ``"in-process"``, ``"privileged"`` or ``"unknown"`` (not recorded).
    task : str
        The task the rows were evaluated on (``solar`` for every run before tasks).
    """

    source: str
    where: str
    setting: str
    protocol: dict[str, Any]
    board_protocol: dict[str, Any]
    metrics: pd.DataFrame
    access: dict[str, str] = field(default_factory=dict)
    task: str = DEFAULT_TASK

    @property
    def protocol_id(self) -> str:
        """The id of the setting's protocol (as ``run_metadata.json`` records it for a run directory)."""
        return protocol_id(self.protocol)

    @property
    def board_id(self) -> str:
        """The id of the protocol without its setting: equal ids share a board."""
        return protocol_id(self.board_protocol)


def board_fingerprint(fingerprint: Mapping[str, Any], config: Any, task: str = DEFAULT_TASK) -> dict[str, Any]:
    """``fingerprint`` without its setting: the comparison key of one board.

    The setting decides the reward's physics switch (``no_physics_penalty``), so the task
    configuration is hashed with that switch off; every other field is kept as it is. A task
    other than ``solar`` is part of the key (``task``), so boards of two tasks never share an id;
    a solar board's key is what it was before tasks.
    """
    board = {key: value for key, value in fingerprint.items() if key != "setting"}
    market = get_task(task)
    board["config_sha256"] = task_config_sha256(market.setting_config(config, no_physics_penalty=False), market)
    if task != DEFAULT_TASK:
        board.setdefault("task", task)
    return board


def run_protocol(metadata: RunMetadata) -> tuple[dict[str, Any], dict[str, Any]]:
    """(fingerprint, board fingerprint) of a run from its ``run_metadata.json``.

    A run that records no ``protocol`` (written before protocols were recorded) is ranked under the
    one :class:`~solarchain_eval.evaluation.run_metadata.RunMetadata` computes for it on read.

    Raises
    ------
    LeaderboardError
        No protocol can be established, the recorded config is not readable, or the recorded
        protocol disagrees with its recorded id or config.
    """
    path = metadata.where
    try:
        config = metadata.task_config()
        fingerprint = metadata.fingerprint()
    except RunMetadataError as error:
        raise LeaderboardError(
            f"{error}; its protocol cannot be compared (evaluate the agent again to rank it)"
        ) from None
    if metadata.protocol_recorded:
        if protocol_id(fingerprint) != metadata.protocol_id:
            raise LeaderboardError(f"{path}: its protocol does not hash to its protocol_id (edited by hand?)")
        if fingerprint.get("config_sha256") != task_config_sha256(config, metadata.resolve_task()):
            raise LeaderboardError(f"{path}: its protocol's config_sha256 does not match its config (edited by hand?)")
    return fingerprint, board_fingerprint(fingerprint, config, metadata.task)


def _check_rollouts(section: Section) -> None:
    """Every policy holds exactly its protocol's rollouts, each once (verify's rule), else refuse."""
    metrics = section.metrics
    problem = rollout_set_problem(
        zip(
            metrics["policy"].astype(str), metrics["run_seed"].astype(int), metrics["episode"].astype(int), strict=True
        ),
        sorted(set(metrics["policy"].astype(str))),
        section.protocol["run_seeds"],
        int(section.protocol["episodes"]),
    )
    if problem is not None:
        raise LeaderboardError(f"{section.where}: {problem}; a board ranks only whole runs")


def _run_sections(source: str, root: Path, metrics: pd.DataFrame, metadata: RunMetadata | None) -> list[Section]:
    if metadata is None:
        raise LeaderboardError(f"{root} has no {METADATA_FILE}; a leaderboard needs every run's protocol")
    fingerprint, board = run_protocol(metadata)
    setting = fingerprint["setting"]
    other = sorted(set(metrics["setting"].astype(str)) - {setting})
    if other:
        raise LeaderboardError(f"{root}: metrics.csv holds setting {other[0]!r} but its protocol is of {setting!r}")
    where = f"{source} [{setting}]"
    return [Section(source, where, setting, fingerprint, board, metrics, dict(metadata.policy_access), metadata.task)]


def _paper_sections(source: str, root: Path, data) -> list[Section]:
    """One section per setting of a paper root, its protocol merged from its finished eval units
    (:func:`~solarchain_eval.evaluation.run_metadata.setting_protocol`, as the paper root records it)."""
    units: dict[str, dict[str, RunMetadata]] = {}
    configs: dict[str, BenchmarkConfig] = {}
    for name, metadata in sorted(data.unit_run_metadata.items()):
        unit_dir = root / UNITS_DIR / "eval" / name
        if not is_done(unit_dir):
            continue
        fingerprint, _ = run_protocol(metadata)  # each unit's own protocol checked
        units.setdefault(fingerprint["setting"], {})[str(unit_dir)] = metadata
        configs.setdefault(fingerprint["setting"], metadata.task_config())
    sections = []
    for setting in data.settings:
        group = units.get(setting)
        if not group:
            raise LeaderboardError(
                f"{source}: no finished evaluation unit under {UNITS_DIR}/eval records the protocol of setting "
                f"{setting!r}; a leaderboard needs every run's protocol"
            )
        try:
            merged = setting_protocol(group)
        except ProtocolMismatch as error:
            raise LeaderboardError(str(error)) from None
        access: dict[str, str] = {}
        for metadata in group.values():
            access.update(metadata.policy_access)
        metrics = data.rollouts(setting).reset_index(drop=True)
        unrecorded = sorted(set(metrics["policy"].astype(str)) - set(access))
        if unrecorded:
            raise LeaderboardError(
                f"{source} [{setting}]: no evaluation unit records policy {unrecorded[0]!r} of combined/{setting}"
            )
        board = board_fingerprint(merged, configs[setting], data.task)
        sections.append(Section(source, f"{source} [{setting}]", setting, merged, board, metrics, access, data.task))
    return sections


def read_input(path: Path, source: str | None = None) -> list[Section]:
    """The sections of a run directory or paper root ``path`` (verified; see the module docstring).

    Raises
    ------
    ReportDataError
        A file is missing, malformed or not vouched for by the run's metadata.
    LeaderboardError
        No protocol can be established, or a policy lacks rollouts its protocol promises.
    """
    path = Path(path)
    return data_sections(load_report_data(path), source or str(path))


def data_sections(data: ReportData, source: str) -> list[Section]:
    """The sections of a run directory or paper root already read (and verified) as ``data``."""
    path = data.root
    run = data.kind == "run"
    sections = (
        _run_sections(source, path, data.metrics, data.run_metadata) if run else _paper_sections(source, path, data)
    )
    for section in sections:
        _check_rollouts(section)
    return sections
