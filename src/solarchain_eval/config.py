"""Benchmark configuration: pydantic models that load the paper's YAML layout unchanged.

Every section forbids unknown keys, so a typo in a config file is an error that names the key
instead of a silently ignored setting. Defaults are those of docs/environment.md#arguments and the paper's
``configs/default.yaml``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator


class ConfigError(ValueError):
    """A configuration file is missing, unreadable or invalid."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)


class MarketConfig(_Section):
    """Market state at reset and the admissible action ranges (dimensionless ratios)."""

    initial_liquidity: float = Field(1.0, ge=0.0, description="Liquidity pool at reset, MWh.")
    initial_token_price: float = Field(1.0, gt=0.0, description="Token price at reset.")
    min_reward_ratio: float = Field(0.05, ge=0.0, le=1.0)
    max_reward_ratio: float = Field(0.65, ge=0.0, le=1.0)
    min_liquidity_ratio: float = Field(0.20, ge=0.0, le=1.0)
    max_liquidity_ratio: float = Field(0.95, ge=0.0, le=1.0)
    max_burn_rate: float = Field(0.20, gt=0.0, le=1.0)
    max_total_allocation: float = Field(0.98, gt=0.0, le=2.0)
    static_reward_ratio: float = 0.25
    static_liquidity_ratio: float = 0.75
    static_burn_rate: float = 0.02

    @model_validator(mode="after")
    def _ranges_ordered(self) -> "MarketConfig":
        if self.min_reward_ratio >= self.max_reward_ratio:
            raise ValueError("market.min_reward_ratio must be below market.max_reward_ratio")
        if self.min_liquidity_ratio >= self.max_liquidity_ratio:
            raise ValueError("market.min_liquidity_ratio must be below market.max_liquidity_ratio")
        return self


class RewardConfig(_Section):
    """Penalty weights of the step reward R = M - λd D - λj J - λu U - λf F - λp (V + A)."""

    drawdown_penalty: float = 1.50
    action_jitter_penalty: float = 0.25
    unmet_demand_penalty: float = 0.40
    physics_penalty: float = 2.00
    fairness_penalty: float = 0.20


class TrainingConfig(_Section):
    """Stable-Baselines3 settings shared by PPO, SAC and DQN."""

    timesteps: int = Field(10_000, ge=1)
    n_envs: int = Field(1, ge=1)
    learning_rate: float = Field(3e-4, gt=0.0)
    batch_size: int = Field(64, ge=1)
    gamma: float = Field(0.98, gt=0.0, le=1.0)


class EvaluationConfig(_Section):
    episodes: int = Field(5, ge=1)
    policies: list[str] = Field(default_factory=lambda: ["static", "random", "myopic"])


class BenchmarkConfig(_Section):
    """Top-level configuration in the layout of the paper's ``configs/*.yaml``."""

    seed: int = 20260511
    episode_steps: int = Field(24, ge=1)
    data_dir: str | None = Field(
        None, description="Dataset directory; None selects the embedded default dataset."
    )
    output_dir: str = "outputs/runs"
    figures_dir: str = "figures"
    action_mode: Literal["continuous", "discrete"] = "continuous"
    discrete_levels: int = Field(5, ge=2)
    no_physics_penalty: bool = False
    market: MarketConfig = Field(default_factory=MarketConfig)
    reward: RewardConfig = Field(default_factory=RewardConfig)
    training: TrainingConfig = Field(default_factory=TrainingConfig)
    evaluation: EvaluationConfig = Field(default_factory=EvaluationConfig)

    def with_updates(self, **updates: Any) -> "BenchmarkConfig":
        """A validated copy with top-level fields replaced (``None`` values are ignored)."""
        payload = self.model_dump()
        payload.update({k: v for k, v in updates.items() if v is not None})
        return BenchmarkConfig.model_validate(payload)


def _format_validation_error(path: Path | str, error: ValidationError) -> str:
    lines = [f"invalid configuration in {path}:"]
    for item in error.errors():
        where = ".".join(str(part) for part in item["loc"]) or "<top level>"
        if item["type"] == "extra_forbidden":
            lines.append(f"  - unknown key '{where}'")
        else:
            lines.append(f"  - {where}: {item['msg']}")
    return "\n".join(lines)


def config_from_mapping(payload: dict[str, Any], source: str = "<mapping>") -> BenchmarkConfig:
    try:
        return BenchmarkConfig.model_validate(payload)
    except ValidationError as error:
        raise ConfigError(_format_validation_error(source, error)) from None


def load_config(path: str | Path) -> BenchmarkConfig:
    """Load a YAML config file; unknown keys and a missing file are errors."""
    config_path = Path(path)
    if not config_path.is_file():
        raise ConfigError(f"config file not found: {config_path}")
    try:
        payload = yaml.safe_load(config_path.read_text(encoding="utf-8"))
    except yaml.YAMLError as error:
        raise ConfigError(f"{config_path} is not valid YAML: {error}") from None
    if payload is None:
        payload = {}
    if not isinstance(payload, dict):
        raise ConfigError(f"{config_path}: the top level must be a mapping of keys to values")
    return config_from_mapping(payload, str(config_path))
