"""A run's protocol as one comparable value: the fingerprint and its short id.

Two results are comparable when their agents faced the same task: the same dataset (sha256 of
every CSV), run seeds, episodes per seed, episode-seed rule, setting, task configuration
(market, reward, episode length, discrete grid), environment version and records schema. The
fingerprint holds exactly those; :func:`protocol_id` is the first 12 hex digits of the sha256 of
its canonical JSON. The package version is recorded beside it, not in it: a release that does not
change the task keeps the id, and a release that changes the dynamics bumps the environment's
registered version (``SolarChainEval-v0`` -> ``-v1``), which changes the id.

What the market contributes comes from its :class:`~solarchain_eval.tasks.base.Task`: its
identity (``env``) and the configuration that decides it (``config_sha256``). A run of a task
other than the solar market also records the task's name (``task``), so the solar market's
fingerprints, and the paper's protocol id, are those of the runs before tasks.

Each agent's action mode is recorded in the fingerprint too (``action_modes``) but not hashed:
the discrete grid is a fixed decoding of the same continuous market (its size is in the task
configuration), so a discrete and a continuous agent are ranked on one board, as in the paper.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

from ..config import TASK_CONFIG_FIELDS as TASK_CONFIG_FIELDS  # re-exported: the solar market's, by config.py
from ..records_schema import RECORDS_SCHEMA_VERSION
from ..tasks.base import Task
from ..tasks.registry import DEFAULT_TASK, get_task

#: Fields of the fingerprint that the id does not hash (see the module docstring).
UNHASHED_FIELDS = ("action_modes",)


def canonical_json(value: Any) -> str:
    """JSON with sorted keys and no whitespace: equal values give equal text."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def task_config_sha256(config: Any, task: Task | None = None) -> str:
    """sha256 of the configuration fields that decide the task (``task.protocol_config``; default: the
    solar market's :data:`TASK_CONFIG_FIELDS`)."""
    return sha256_text(canonical_json((task or get_task()).protocol_config(config)))


def protocol_fingerprint(
    *,
    dataset_sha256: Mapping[str, str],
    run_seeds: Sequence[int],
    episodes: int,
    episode_seed_rule: str,
    setting: str,
    config: Any,
    action_modes: Mapping[str, str],
    task: Task | None = None,
) -> dict[str, Any]:
    """The fingerprint ``run_metadata.json`` records under ``protocol``.

    Parameters
    ----------
    dataset_sha256 : mapping
        Dataset CSV name -> sha256 (the run metadata's ``dataset.files``).
    run_seeds, episodes, episode_seed_rule, setting
        The evaluation protocol (``episode_seed_rule``: a name in ``protocol.EPISODE_SEED_RULES``).
    config
        The task's resolved configuration (its reward setting applied).
    action_modes : mapping
        Policy name -> ``"continuous"`` or ``"discrete"``.
    task : Task, optional
        The market evaluated (default: the solar market).
    """
    task = task or get_task()
    # the task's name only when it is not the solar market: the solar fingerprints stay those before tasks
    named = {} if task.name == DEFAULT_TASK else {"task": task.name}
    return {
        **named,
        **task.identity(config),
        "records_schema_version": RECORDS_SCHEMA_VERSION,
        "dataset_sha256": dict(sorted(dataset_sha256.items())),
        "run_seeds": [int(s) for s in run_seeds],
        "episodes": int(episodes),
        "episode_seed_rule": str(episode_seed_rule),
        "setting": str(setting),
        "config_sha256": task_config_sha256(config, task),
        "action_modes": dict(sorted(action_modes.items())),
    }


def protocol_id(fingerprint: Mapping[str, Any]) -> str:
    """The short id of a fingerprint: 12 hex digits of the sha256 of its hashed fields."""
    hashed = {key: value for key, value in fingerprint.items() if key not in UNHASHED_FIELDS}
    return sha256_text(canonical_json(hashed))[:12]


def protocol_difference(first: Mapping[str, Any], second: Mapping[str, Any]) -> str | None:
    """The first hashed field in which two fingerprints differ (None when their ids agree)."""
    for key in sorted(set(first) | set(second)):
        if key not in UNHASHED_FIELDS and first.get(key) != second.get(key):
            return key
    return None


def merge_fingerprints(fingerprints: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One fingerprint for runs that split one protocol by run seed or policy (a grid's units).

    Run seeds are united (sorted) and action modes merged; every other field must agree.

    Raises
    ------
    ValueError
        Two fingerprints differ in another field (the message names it).
    """
    if not fingerprints:
        raise ValueError("no fingerprints to merge")
    merged = dict(fingerprints[0])
    seeds = set(merged["run_seeds"])
    modes = dict(merged.get("action_modes", {}))
    for other in fingerprints[1:]:
        for key in sorted(set(merged) | set(other)):
            if key not in ("run_seeds", "action_modes") and merged.get(key) != other.get(key):
                raise ValueError(
                    f"the runs differ in protocol field '{key}': {merged.get(key)!r} vs {other.get(key)!r}"
                )
        seeds.update(other["run_seeds"])
        modes.update(other.get("action_modes", {}))
    merged["run_seeds"] = sorted(int(s) for s in seeds)
    merged["action_modes"] = dict(sorted(modes.items()))
    return merged
