"""Benchmark configuration: pydantic models that load the paper's YAML layout unchanged.

Every section forbids unknown keys, so a typo in a config file is an error that names the key
instead of a silently ignored setting. Defaults are those of docs/environment.md#arguments and the paper's
``configs/default.yaml``.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from .common.errors import OptionsError
from .protocol import PAPER_EPISODES, PAPER_SEED


class ConfigError(OptionsError, ValueError):
    """A configuration file is missing, unreadable or invalid."""


#: Seeds feed numpy's legacy and torch seeding, whose range is 0 .. 2**32 - 1.
MAX_SEED = 2**32 - 1
#: Penalty weights and market magnitudes are bounded so that no value overflows a step's arithmetic.
MAX_WEIGHT = 1e6
#: levels**3 discrete actions: 50 levels already give 125,000.
MAX_DISCRETE_LEVELS = 50


class _Section(BaseModel):
    # NaN and ±inf are refused everywhere: one of them would make every metric NaN.
    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False, allow_inf_nan=False)


class MarketConfig(_Section):
    """Market state at reset and the admissible action ranges (dimensionless ratios)."""

    initial_liquidity: float = Field(1.0, ge=0.0, le=MAX_WEIGHT, description="Liquidity pool at reset, MWh.")
    initial_token_price: float = Field(1.0, gt=0.0, le=MAX_WEIGHT, description="Token price at reset.")
    min_reward_ratio: float = Field(0.05, ge=0.0, le=1.0)
    max_reward_ratio: float = Field(0.65, ge=0.0, le=1.0)
    min_liquidity_ratio: float = Field(0.20, ge=0.0, le=1.0)
    max_liquidity_ratio: float = Field(0.95, ge=0.0, le=1.0)
    max_burn_rate: float = Field(0.20, gt=0.0, le=1.0)
    max_total_allocation: float = Field(0.98, gt=0.0, le=2.0)
    static_reward_ratio: float = Field(0.25, ge=0.0, le=1.0)
    static_liquidity_ratio: float = Field(0.75, ge=0.0, le=1.0)
    static_burn_rate: float = Field(0.02, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _ranges_ordered(self) -> MarketConfig:
        if self.min_reward_ratio >= self.max_reward_ratio:
            raise ValueError("market.min_reward_ratio must be below market.max_reward_ratio")
        if self.min_liquidity_ratio >= self.max_liquidity_ratio:
            raise ValueError("market.min_liquidity_ratio must be below market.max_liquidity_ratio")
        # The static action is the first step's previous action (not sanitized), so it must be admissible.
        for name, low, high in (
            ("static_reward_ratio", self.min_reward_ratio, self.max_reward_ratio),
            ("static_liquidity_ratio", self.min_liquidity_ratio, self.max_liquidity_ratio),
            ("static_burn_rate", 0.0, self.max_burn_rate),
        ):
            if not low <= getattr(self, name) <= high:
                raise ValueError(f"market.{name} = {getattr(self, name)} is outside its range [{low}, {high}]")
        return self


class RewardConfig(_Section):
    """Penalty weights of the step reward R = M - λd D - λj J - λu U - λf F - λp (V + A)."""

    drawdown_penalty: float = Field(1.50, ge=0.0, le=MAX_WEIGHT)
    action_jitter_penalty: float = Field(0.25, ge=0.0, le=MAX_WEIGHT)
    unmet_demand_penalty: float = Field(0.40, ge=0.0, le=MAX_WEIGHT)
    physics_penalty: float = Field(2.00, ge=0.0, le=MAX_WEIGHT)
    fairness_penalty: float = Field(0.20, ge=0.0, le=MAX_WEIGHT)


class TrainingConfig(_Section):
    """Stable-Baselines3 settings shared by PPO, SAC and DQN."""

    timesteps: int = Field(10_000, ge=1, le=10**12)
    n_envs: int = Field(1, ge=1, le=4096)
    learning_rate: float = Field(3e-4, gt=0.0, le=1.0)
    batch_size: int = Field(64, ge=1, le=10**7)
    gamma: float = Field(0.98, gt=0.0, le=1.0)


class EvaluationConfig(_Section):
    """Defaults of ``evaluate``'s ``--episodes`` and ``--policies`` (the options win when given)."""

    episodes: int = Field(PAPER_EPISODES, ge=1, le=10**6, description="Episodes per run seed.")
    policies: list[str] = Field(default_factory=lambda: ["static", "random", "myopic"], min_length=1)


#: The :class:`BenchmarkConfig` fields that decide the solar market's task (hashed into a run's protocol);
#: paths, training budgets and evaluation defaults do not. ``start_days`` is hashed only when set, so
#: that a run on every start day keeps the protocol id it had before the field existed.
TASK_CONFIG_FIELDS = ("episode_steps", "discrete_levels", "no_physics_penalty", "market", "reward", "start_days")
#: The largest day number ``start_days`` accepts (a dataset of 27 years of days).
MAX_START_DAY = 10_000


def parse_start_days(value: Any) -> list[int] | None:
    """``start_days`` as sorted day numbers: a list of integers, or text such as ``"1-21"`` or ``"1-7,15"``.

    Raises
    ------
    ValueError
        A day below 1 or above :data:`MAX_START_DAY`, a day given twice, an empty list, a reversed
        range or text that is not days and ranges (the message names the part at fault).
    """
    if value is None:
        return None
    if isinstance(value, str):
        days: list[int] = []
        for part in value.replace(" ", "").split(","):
            first, dash, last = part.partition("-")
            if not first.isdigit() or (dash and not last.isdigit()):
                raise ValueError(f"'{part}' is neither a day nor a range of days such as 1-21")
            low, high = int(first), int(last) if dash else int(first)
            if high < low:
                raise ValueError(f"the range '{part}' ends before it starts")
            days.extend(range(low, min(high, MAX_START_DAY + 1) + 1))
        value = days
    if isinstance(value, (bool, int)) or not isinstance(value, (list, tuple)):
        raise ValueError("give a list of day numbers or text such as '1-21'")
    days = []
    for day in value:
        if isinstance(day, bool) or not isinstance(day, int):
            raise ValueError(f"{day!r} is not a day number (1 = the dataset's first day)")
        if not 1 <= day <= MAX_START_DAY:
            raise ValueError(f"day {day} is outside 1..{MAX_START_DAY} (1 = the dataset's first day)")
        days.append(int(day))
    if not days:
        raise ValueError("give at least one day (or leave start_days unset for every day)")
    repeated = sorted({day for day in days if days.count(day) > 1})
    if repeated:
        raise ValueError(f"day(s) {', '.join(map(str, repeated))} given twice")
    return sorted(days)


class BenchmarkConfig(_Section):
    """Top-level configuration in the layout of the paper's ``configs/*.yaml``."""

    seed: int = Field(PAPER_SEED, ge=0, le=MAX_SEED)
    episode_steps: int = Field(24, ge=1, le=10**6, description="Steps per episode; at most the dataset's hours.")
    data_dir: str | None = Field(None, description="Dataset directory; None selects the embedded default dataset.")
    output_dir: str = "outputs/runs"
    action_mode: Literal["continuous", "discrete"] = "continuous"
    discrete_levels: int = Field(5, ge=2, le=MAX_DISCRETE_LEVELS)
    no_physics_penalty: bool = False
    start_days: list[int] | None = Field(
        None,
        description="Days an episode may start on (1 = the dataset's first day; a list or text such as "
        "'1-21'); None: every day with a full episode after it.",
    )
    market: MarketConfig = Field(default_factory=MarketConfig)
    reward: RewardConfig = Field(default_factory=RewardConfig)
    training: TrainingConfig = Field(default_factory=TrainingConfig)
    evaluation: EvaluationConfig = Field(default_factory=EvaluationConfig)

    @field_validator("start_days", mode="before")
    @classmethod
    def _start_days(cls, value: Any) -> list[int] | None:
        return parse_start_days(value)

    def with_updates(self, **updates: Any) -> BenchmarkConfig:
        """A validated copy with top-level fields replaced (``None`` values are ignored)."""
        payload = self.model_dump()
        payload.update({k: v for k, v in updates.items() if v is not None})
        return BenchmarkConfig.model_validate(payload)


def _format_validation_error(path: Path | str, error: ValidationError) -> str:
    # One line: every problem, each naming its key.
    problems = []
    for item in error.errors():
        where = ".".join(str(part) for part in item["loc"]) or "<top level>"
        if item["type"] == "extra_forbidden":
            problems.append(f"unknown key '{where}'")
        else:
            problems.append(f"{where}: {item['msg']}")
    return f"invalid configuration in {path}: " + "; ".join(problems)


#: Keys of the original release's YAML that SolarChain-Eval has no use for: accepted, dropped with a
#: warning that says why (so the paper's configs load unchanged, and nothing is silently ignored).
RETIRED_KEYS = {
    "figures_dir": "the report writes its figures under <run or root>/report/figures (report --out moves it)",
}


def config_from_mapping(payload: dict[str, Any], source: str = "<mapping>") -> BenchmarkConfig:
    payload = dict(payload)
    for key, reason in RETIRED_KEYS.items():
        if key in payload:
            del payload[key]
            warnings.warn(f"{source}: '{key}' is not used ({reason}); ignoring it", UserWarning, stacklevel=2)
    try:
        return BenchmarkConfig.model_validate(payload)
    except ValidationError as error:
        raise ConfigError(_format_validation_error(source, error)) from None


def check_episode_fits(config: BenchmarkConfig, hours: int, source: str = "the dataset") -> None:
    """Refuse an ``episode_steps`` longer than the dataset (it would repeat the last hour)."""
    if config.episode_steps > hours:
        raise ConfigError(f"episode_steps = {config.episode_steps} is longer than {source}, which has {hours} hours")


def select_starts(
    starts: np.ndarray, start_days: list[int] | None, steps_per_day: int, source: str = "the dataset"
) -> np.ndarray:
    """The admissible episode starts (row indices) on ``start_days`` (all of ``starts`` when None).

    A start's day is ``start // steps_per_day + 1``. Every listed day must be one of the starts'
    days: a day without a full episode after it (or, for a market whose episodes start on given
    weekdays, another day) is refused, naming the day and the days there are.

    Raises
    ------
    ConfigError
        A listed day that is not an admissible start day of ``source``.
    """
    if start_days is None:
        return starts
    days = starts // int(steps_per_day) + 1
    missing = sorted(set(start_days) - set(days.tolist()))
    if missing:
        shown = ", ".join(map(str, missing[:5])) + (", ..." if len(missing) > 5 else "")
        raise ConfigError(
            f"start_days: day(s) {shown} of {source} have no episode start (its start days are "
            f"{_day_ranges(days.tolist())}: days with a full episode after them)"
        )
    return starts[np.isin(days, start_days)]


def _day_ranges(days: list[int]) -> str:
    """``[1, 2, 3, 8]`` -> ``"1-3, 8"``."""
    out: list[str] = []
    for day in days:
        if out and day == int(out[-1].rpartition("-")[2]) + 1:
            out[-1] = f"{out[-1].partition('-')[0]}-{day}"
        else:
            out.append(str(day))
    return ", ".join(out)


def check_seeds(seeds: list[int] | tuple[int, ...]) -> None:
    """Refuse negative, too large or repeated run seeds (a repeat would count one run twice)."""
    for seed in seeds:
        if not 0 <= seed <= MAX_SEED:
            raise ConfigError(f"seed {seed} is outside 0..{MAX_SEED}")
    repeated = sorted({seed for seed in seeds if list(seeds).count(seed) > 1})
    if repeated:
        raise ConfigError(f"seed(s) {', '.join(map(str, repeated))} given twice; each run seed must be distinct")


class _UniqueKeyLoader(yaml.SafeLoader):
    """A safe YAML loader that refuses a key given twice in one mapping (YAML keeps the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(None, None, f"duplicate key '{key}'", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _read_text(config_path: Path) -> str:
    try:
        raw = config_path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {config_path}") from None
    except IsADirectoryError:
        raise ConfigError(f"config file {config_path} is a directory, not a file") from None
    except PermissionError:
        raise ConfigError(f"config file {config_path}: permission denied (this user cannot read it)") from None
    except OSError as error:
        raise ConfigError(f"config file {config_path} cannot be read: {error.strerror or error}") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise ConfigError(
            f"{config_path} is not UTF-8 text (byte {raw[error.start]:#04x} at offset {error.start})"
        ) from None


def load_config(path: str | Path) -> BenchmarkConfig:
    """Load a YAML config file; unknown or repeated keys and an unreadable file are errors."""
    config_path = Path(path)
    text = _read_text(config_path)
    try:
        payload = yaml.load(text, Loader=_UniqueKeyLoader)  # a SafeLoader subclass
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        if mark is not None:
            detail = f"{getattr(error, 'problem', None) or error} (line {mark.line + 1}, column {mark.column + 1})"
        else:
            detail = " ".join(str(error).split())
        raise ConfigError(f"{config_path} is not valid YAML: {detail}") from None
    if payload is None:
        payload = {}
    if not isinstance(payload, dict):
        raise ConfigError(f"{config_path}: the top level must be a mapping of keys to values")
    return config_from_mapping(payload, str(config_path))


#: The YAML reading every configuration-like file shares (the sweep file too): the text of a file
#: with one-line errors, and the loader that refuses repeated keys.
read_config_text = _read_text
UniqueKeyLoader = _UniqueKeyLoader
