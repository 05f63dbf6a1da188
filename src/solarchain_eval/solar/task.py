"""The solar market as a :class:`~solarchain_eval.tasks.base.Task`: the benchmark's first task.

Everything the generic wings need from the market goes through :data:`SOLAR_TASK`: where its
dataset is and how it loads, its environment, the per-step fields and episode metrics of its
records, its protocol identity and its baselines. Its internals are :mod:`solarchain_eval.data`
(weather to hourly table), :mod:`solarchain_eval.market` (the dynamics) and
:mod:`solarchain_eval.envs` (the environments).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BenchmarkConfig, MarketConfig
from ..data.default import resolve_data_dir
from ..data.files import MANIFEST_FILE
from ..data.provenance import dataset_provenance
from ..data.published import PAPER_DATASET_SHA256
from ..data.table import HourlyTable, load_table
from ..envs.env import SolarChainEnv
from ..envs.registration import ENV_ID
from ..envs.step_info import STEP_INFO_KEYS
from ..market.baselines import BASELINES, make_baseline
from ..market.observation import OBSERVATION_NAMES
from ..records_schema import EPISODE_METRIC_COLUMNS
from ..tasks.base import Lever, MetricSpec, PaperReference, TrainLogField
from ..tasks.benchmark_config import BenchmarkConfigMethods
from ..tasks.dataset import DatasetBuilder
from .dataset import SOLAR_DATASET
from .governance_view import SolarGovernanceView
from .metrics import episode_metrics_from_steps

_DEFAULT_MARKET = MarketConfig()
#: The three levers in [0, 1]³ the agent sets, with the ranges they execute in under the default config.
SOLAR_LEVERS = (
    Lever(
        "reward_ratio",
        "–",
        _DEFAULT_MARKET.min_reward_ratio,
        _DEFAULT_MARKET.max_reward_ratio,
        "α: the share of matched value paid to producers as reward",
    ),
    Lever(
        "liquidity_ratio",
        "–",
        _DEFAULT_MARKET.min_liquidity_ratio,
        _DEFAULT_MARKET.max_liquidity_ratio,
        "ℓ: the share of reported supply made available to the market",
    ),
    Lever("burn_rate", "–", 0.0, _DEFAULT_MARKET.max_burn_rate, "b: the share of the token supply burnt each hour"),
)
#: Each episode metric's template dimension and direction (docs/metrics.md).
_DECLARED = {
    "cumulative_reward": ("utility", "higher"),
    "episode_volume": ("utility", "higher"),
    "physics_violation_rate": ("safety", "lower"),
    "max_drawdown": ("stability", "lower"),
    "max_token_drawdown": ("stability", "lower"),
    "action_jitter": ("stability", "lower"),
    "mean_slippage": ("stability", "lower"),
    "spatial_fairness_index": ("fairness", "lower"),
    "artificial_liquidity_MWh": ("safety", "lower"),
    "final_liquidity": ("utility", "none"),
    "final_token_price": ("stability", "none"),
}
SOLAR_METRICS = tuple(MetricSpec(column, *_DECLARED[column.name]) for column in EPISODE_METRIC_COLUMNS)
#: training_log.csv's market columns: volume, V and artificial liquidity as in the evaluation metrics, and the cost.
SOLAR_TRAINING_LOG = (
    TrainLogField("episode_volume", "matched_energy_MWh"),
    TrainLogField("physics_violation_rate", "physics_violation_rate", mean=True),
    TrainLogField("artificial_liquidity_MWh", "artificial_liquidity_MWh"),
    TrainLogField("episode_cost", "cost"),
)

# --- the report's and the leaderboard's concern: the paper's reference ---
#: What the paper published: its dataset, the metrics its tables cover and its board's columns.
SOLAR_PAPER_REFERENCE = PaperReference(
    dataset_sha256=PAPER_DATASET_SHA256,
    metrics=tuple(column.name for column in EPISODE_METRIC_COLUMNS),
    board_metrics=(
        "physics_violation_rate",
        "artificial_liquidity_MWh",
        "mean_slippage",
        "action_jitter",
        "spatial_fairness_index",
    ),
    headers={
        "cumulative_reward": "reward",
        "physics_violation_rate": "Violation rate",
        "artificial_liquidity_MWh": "Artificial liquidity (MWh)",
        "mean_slippage": "Slippage",
        "action_jitter": "Action jitter",
        "spatial_fairness_index": "Fairness index",
    },
)


@dataclass(frozen=True)
class SolarTask(BenchmarkConfigMethods):
    """The solar market (see the module docstring); use :data:`SOLAR_TASK`."""

    name: str = "solar"
    env_id: str = ENV_ID
    levers: tuple[Lever, ...] = SOLAR_LEVERS
    step_fields: tuple[str, ...] = STEP_INFO_KEYS
    metrics: tuple[MetricSpec, ...] = SOLAR_METRICS
    #: The observation's features, in order (optional Task attribute: agents/ reads it through the task).
    observation_names: tuple[str, ...] = OBSERVATION_NAMES
    # --- the report's and the leaderboard's concern (optional Task attributes, tasks/base.py) ---
    paper_reference: PaperReference | None = SOLAR_PAPER_REFERENCE
    dataset_manifest: str | None = MANIFEST_FILE
    # --- data, sweep and bench-scale's concern: building and checking datasets (tasks/dataset.py) ---
    dataset: DatasetBuilder | None = SOLAR_DATASET
    #: The sweep's episode cost, Σ_t (V_t + A_t), from these step fields (tasks/base.py episode_cost_fields).
    episode_cost_fields: tuple[str, ...] = ("physics_violation_rate", "unsafe_backed_MWh")

    def data_dir(self, data_dir: str | Path | None, config: Any) -> Path:
        return resolve_data_dir(data_dir, getattr(config, "data_dir", None))

    def load_data(self, data_dir: Path) -> HourlyTable:
        return load_table(data_dir)

    def provenance(self, data: HourlyTable) -> dict[str, Any]:
        return dataset_provenance(data)

    def make_env(self, config: BenchmarkConfig, data: HourlyTable, *, action_mode: str | None = None) -> SolarChainEnv:
        return SolarChainEnv(config=config, table=data, action_mode=action_mode)

    def episode_metrics(self, steps: Mapping[str, list], env: SolarChainEnv) -> dict[str, float]:
        return episode_metrics_from_steps(steps, np.asarray(list(env.city_totals.values())))

    def step_extras(self, info: Mapping[str, Any]) -> tuple[float, ...]:
        return tuple(info["city_rewards"].values())

    # --- governance: the view the Planner/Auditor layer and the LLM agent read (tasks/governance_view.py)
    def governance_view(self, config: Any = None) -> SolarGovernanceView:
        """The market as the governance layer sees it, for a benchmark config or its market section."""
        return SolarGovernanceView.from_config(config)

    def identity(self, config: BenchmarkConfig) -> dict[str, Any]:
        return {"env": self.env_id, **self.start_days_identity(config)}

    def baselines(self) -> Mapping[str, Callable[..., Any]]:
        return {name: (lambda config, _name=name: make_baseline(_name, config.market)) for name in BASELINES}

    # -- evaluation and records (the runner, run_metadata.json, the fingerprint, verify) --

    def step_extra_names(self, data: HourlyTable) -> tuple[str, ...]:
        return tuple(data.cities)

    # --- training's concern: vector and JAX environments, the training log (tasks/base.py) ---
    training_log: tuple[TrainLogField, ...] = SOLAR_TRAINING_LOG

    def make_vector_env(
        self,
        config: BenchmarkConfig,
        data: HourlyTable,
        n_envs: int,
        *,
        action_mode: str | None = None,
        autoreset_mode: str | None = None,
    ) -> Any:
        """The native batched env (:class:`~solarchain_eval.envs.vector.SolarChainVectorEnv`)."""
        from ..envs.vector import SolarChainVectorEnv

        reset = {"autoreset_mode": autoreset_mode} if autoreset_mode is not None else {}
        return SolarChainVectorEnv(n_envs, config=config, table=data, action_mode=action_mode, **reset)

    def make_jax_env(self, config: BenchmarkConfig, data: HourlyTable, *, action_mode: str | None = None) -> Any:
        """The jittable env (:class:`~solarchain_eval.envs.jax_env.SolarChainJaxEnv`; needs the jax extra)."""
        from ..envs.jax_env import SolarChainJaxEnv, make_env_params

        return SolarChainJaxEnv(make_env_params(table=data, config=config, action_mode=action_mode))


#: The solar market task (registered as ``solar`` in :mod:`solarchain_eval.tasks.registry`).
SOLAR_TASK = SolarTask()
