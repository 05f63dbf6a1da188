"""Which sections of a leaderboard's inputs share a board: one task, one protocol apart from the
setting (docs/comparing_results.md), and each policy once per setting.

:func:`check_one_task` and :func:`check_one_protocol` refuse a mix in one line naming two inputs;
:func:`group_by_protocol` splits the sections into boards (``leaderboard --split``);
:func:`merge_by_setting` keeps each policy once, dropping a row-for-row repeat with a note.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import pandas as pd

from ...evaluation.fingerprint import protocol_difference
from .sections import LeaderboardError, Section


def _short(value: Any) -> str:
    if isinstance(value, str) and len(value) == 64:
        return value[:12]  # a sha256
    return json.dumps(value, sort_keys=True) if not isinstance(value, str) else value


def describe_difference(field_name: str, first: Mapping[str, Any], second: Mapping[str, Any]) -> str:
    """``field (a vs b)``, naming the first differing entry of a mapping (``dataset_sha256[p2p_trades.csv]``)."""
    a, b = first.get(field_name), second.get(field_name)
    if isinstance(a, dict) and isinstance(b, dict):
        key = next(k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k))
        return f"{field_name}[{key}] ({_short(a.get(key, 'absent'))} vs {_short(b.get(key, 'absent'))})"
    return f"{field_name} ({_short(a)} vs {_short(b)})"


def check_one_task(sections: Sequence[Section]) -> None:
    """Refuse sections of different tasks: a board ranks the policies of one task.

    Raises
    ------
    LeaderboardError
        One line naming two inputs and their tasks.
    """
    first = sections[0]
    other = next((s for s in sections if s.task != first.task), None)
    if other is not None:
        raise LeaderboardError.about(
            "{a} was evaluated on task {task_a!r} and {b} on task {task_b!r}; a board ranks one task "
            "({opt_split} writes one board per task and protocol)",
            a=first.where,
            task_a=first.task,
            b=other.where,
            task_b=other.task,
        )


def check_one_protocol(sections: Sequence[Section]) -> None:
    """Refuse sections that do not share one protocol apart from their setting.

    Raises
    ------
    LeaderboardError
        One line naming the first differing field and the two inputs.
    """
    first = sections[0]
    for other in sections[1:]:
        differs = protocol_difference(first.board_protocol, other.board_protocol)
        if differs is not None:
            raise LeaderboardError.about(
                "{a} and {b} were evaluated under different protocols: {difference} differs; a board ranks one "
                "protocol ({opt_split} writes one board per protocol)",
                a=first.where,
                b=other.where,
                difference=describe_difference(differs, first.board_protocol, other.board_protocol),
            )
    settings: dict[str, Section] = {}
    for section in sections:  # one setting, one reward: caught here only if a run's label hid its switch
        same = settings.setdefault(section.setting, section)
        differs = protocol_difference(same.protocol, section.protocol)
        if differs is not None:
            raise LeaderboardError(
                f"{same.where} and {section.where} were evaluated under different protocols: "
                f"{describe_difference(differs, same.protocol, section.protocol)} differs"
            )


def group_by_protocol(sections: Sequence[Section]) -> dict[str, list[Section]]:
    """Sections by board id (the protocol without its setting; a task other than solar is part of
    it), in the order the inputs were given."""
    groups: dict[str, list[Section]] = {}
    for section in sections:
        groups.setdefault(section.board_id, []).append(section)
    return groups


def _rows_text(metrics: pd.DataFrame) -> str:
    # A paper root's frame holds every setting's columns; those a setting never fills are empty.
    ordered = metrics.dropna(axis=1, how="all").sort_values(["run_seed", "episode"], kind="stable")
    return ordered[sorted(ordered.columns)].to_csv(index=False)


def merge_by_setting(sections: Sequence[Section]) -> tuple[dict[str, list[Section]], list[str]]:
    """Sections by setting with every policy once; identical duplicates are dropped with a note.

    Returns
    -------
    (dict, list of str)
        Setting -> its sections (duplicated policies removed from the later ones), and the notes.

    Raises
    ------
    LeaderboardError
        A policy name holds different rollouts in two inputs of one setting.
    """
    by_setting: dict[str, list[Section]] = {}
    owner: dict[tuple[str, str], Section] = {}
    notes: list[str] = []
    for section in sections:
        keep = []
        for policy, rows in section.metrics.groupby("policy", sort=False):
            # names are one name whatever their case, as within a run (agents/specs.check_unique)
            first = owner.get((section.setting, str(policy).lower()))
            if first is None:
                owner[(section.setting, str(policy).lower())] = section
                keep.append(policy)
                continue
            other = next(p for p in first.metrics["policy"].unique() if str(p).lower() == str(policy).lower())
            if other != policy:
                raise LeaderboardError(
                    f"policy {policy!r} of {section.source} and {other!r} of {first.source} (setting "
                    f"{section.setting!r}) differ only in case; a board ranks each name once (rename one)"
                )
            earlier = first.metrics[first.metrics["policy"] == policy]
            if _rows_text(earlier) != _rows_text(rows):
                raise LeaderboardError(
                    f"policy {policy!r} of setting {section.setting!r} is in both {first.source} and "
                    f"{section.source} with different results; a board ranks each name once (rename one)"
                )
            notes.append(
                f"{policy} in {section.setting}: {section.source} repeats {first.source} row for row (kept once)"
            )
        if keep:
            kept = section.metrics[section.metrics["policy"].isin(keep)].reset_index(drop=True)
            # replace keeps the section's kind (a suite root's section stays one)
            by_setting.setdefault(section.setting, []).append(replace(section, metrics=kept))
    return by_setting, notes
