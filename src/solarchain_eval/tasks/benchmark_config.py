"""The config methods of a task configured by :class:`~solarchain_eval.config.BenchmarkConfig`.

The solar market and the supply-chain market share the benchmark's config model (seed, episode
length, action mode, reward weights, the penalty switch), so the five :class:`~.base.Task` methods
that read and record it are written once here and mixed into both.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..config import TASK_CONFIG_FIELDS, BenchmarkConfig


class BenchmarkConfigMethods:
    """:class:`~.base.Task`'s config methods for ``BenchmarkConfig`` (mix into a task class)."""

    def default_config(self) -> BenchmarkConfig:
        return BenchmarkConfig()

    def setting_config(self, config: BenchmarkConfig, *, no_physics_penalty: bool) -> BenchmarkConfig:
        return config.with_updates(no_physics_penalty=no_physics_penalty)

    def config_record(self, config: BenchmarkConfig) -> dict[str, Any]:
        return config.model_dump()

    def config_from_record(self, record: Mapping[str, Any]) -> BenchmarkConfig:
        return BenchmarkConfig.model_validate(record)

    def protocol_config(self, config: BenchmarkConfig) -> dict[str, Any]:
        fields = config.model_dump(include=set(TASK_CONFIG_FIELDS))
        if fields.get("start_days") is None:  # every start day: the protocol as before the field existed
            fields.pop("start_days", None)
        return fields

    def start_days_identity(self, config: BenchmarkConfig) -> dict[str, Any]:
        """``{"start_days": [...]}`` for a run restricted to some start days, else nothing: the fingerprint
        shows the restriction by name (and a run on every day keeps the fields it had before)."""
        return {} if config.start_days is None else {"start_days": list(config.start_days)}

    def episode_steps(self, config: BenchmarkConfig) -> int:
        return config.episode_steps
