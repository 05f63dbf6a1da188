"""The supply-chain allocation market as a :class:`~solarchain_eval.tasks.base.Task` (``supply-chain``).

The template's second market (docs/tasks/supply_chain.md): warehouses and suppliers in five
regions, spoofed inventory reports in place of false generation records, and a feasibility oracle
(stock on hand and arriving by tomorrow, within lane capacity) in place of the PV physics check.
Its internals are the modules of this wing; it uses the benchmark's :class:`~solarchain_eval.config.BenchmarkConfig`
(seed, episode length, action mode, reward weights, and ``no_physics_penalty``, which here removes
the feasibility term from the reward).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BenchmarkConfig
from ..tasks.base import Lever, MetricSpec
from ..tasks.benchmark_config import BenchmarkConfigMethods
from ..tasks.dataset import ScenarioDatasetBuilder
from .baselines import SUPPLY_BASELINES, make_supply_baseline
from .dataset import SUPPLY_DATASET
from .env import OBSERVATION_NAMES, STEP_FIELDS, SupplyChainEnv
from .governance_view import SupplyGovernanceView
from .metrics import SUPPLY_METRICS, supply_episode_metrics
from .registration import SUPPLY_ENV_ID
from .table import SupplyTable, default_supply_dir, load_supply_table, supply_provenance

SUPPLY_LEVERS = (
    Lever("supplier_incentive", "–", 0.0, 1.0, "κ: production ordered, as a share of the suppliers' capacity"),
    Lever("release_ratio", "–", 0.0, 1.0, "ρ: the share of reported stock made allocable to retailer orders"),
    Lever("demand_damping", "–", 0.0, 1.0, "δ: damping of retailer orders (sheds up to 40 %)"),
)


@dataclass(frozen=True)
class SupplyChainTask(BenchmarkConfigMethods):
    """The supply-chain market (see the module docstring); use :data:`SUPPLY_TASK`."""

    name: str = "supply-chain"
    env_id: str = SUPPLY_ENV_ID
    levers: tuple[Lever, ...] = SUPPLY_LEVERS
    step_fields: tuple[str, ...] = STEP_FIELDS
    metrics: tuple[MetricSpec, ...] = SUPPLY_METRICS
    #: What a results table in the terminal shows: reward, the oracle's two safety measures, the
    #: bullwhip ratio and the fairness measure (``metrics.csv`` has every metric).
    headline_metrics: tuple[str, ...] = (
        "cumulative_reward",
        "fill_volume_units",
        "violation_rate",
        "phantom_backed_units",
        "bullwhip_ratio",
        "fill_rate_variance",
    )
    observation_names: tuple[str, ...] = OBSERVATION_NAMES
    #: One step is one day: an episode's ``start_hour`` (its first step) is its start day, the
    #: report's resampling unit (:func:`~solarchain_eval.tasks.base.steps_per_day_of`).
    steps_per_day: int = 1
    # --- sweep's concern: datasets built from a seed, dates and a phantom-stock scenario (tasks/dataset.py)
    dataset: ScenarioDatasetBuilder | None = SUPPLY_DATASET

    def data_dir(self, data_dir: str | Path | None, config: Any) -> Path:
        if data_dir:
            return Path(data_dir)
        configured = getattr(config, "data_dir", None)
        return Path(configured) if configured else default_supply_dir()

    def load_data(self, data_dir: Path) -> SupplyTable:
        return load_supply_table(data_dir)

    def provenance(self, data: SupplyTable) -> dict[str, Any]:
        return supply_provenance(data)

    def make_env(
        self, config: BenchmarkConfig | None, data: SupplyTable, *, action_mode: str | None = None
    ) -> SupplyChainEnv:
        return SupplyChainEnv(config=config, table=data, action_mode=action_mode)

    def make_vector_env(
        self,
        config: BenchmarkConfig | None,
        data: SupplyTable,
        n_envs: int,
        *,
        action_mode: str | None = None,
        autoreset_mode: str | None = None,
    ) -> Any:
        """The native batched env (:class:`~.vector.SupplyChainVectorEnv`).

        Raises
        ------
        ValueError
            ``autoreset_mode`` is not ``"NextStep"`` (the only mode it implements).
        """
        from gymnasium.vector import AutoresetMode

        from .vector import SupplyChainVectorEnv

        if autoreset_mode is not None and AutoresetMode(autoreset_mode) != AutoresetMode.NEXT_STEP:
            raise ValueError(f"the supply-chain vector env autoresets NEXT_STEP only, not {autoreset_mode}")
        return SupplyChainVectorEnv(n_envs, config=config, table=data, action_mode=action_mode)

    def make_jax_env(self, config: BenchmarkConfig | None, data: SupplyTable, *, action_mode: str | None = None) -> Any:
        """The env's JAX twin (a gymnax :class:`~.jax_env.SupplyChainJaxEnv`; its params are ``default_params``).

        Needs the optional JAX dependencies; imported here so that the task loads without them.
        """
        from .jax_env import make_supply_jax_env

        return make_supply_jax_env(config, data, action_mode=action_mode)

    def episode_metrics(self, steps: Mapping[str, list], env: SupplyChainEnv) -> dict[str, float]:
        return supply_episode_metrics(steps, np.asarray(list(env.region_totals.values())))

    def step_extras(self, info: Mapping[str, Any]) -> tuple[float, ...]:
        return tuple(info["region_fill_rates"].values())

    def identity(self, config: Any) -> dict[str, Any]:
        return {"env": self.env_id, **self.start_days_identity(config)}

    def step_extra_names(self, data: SupplyTable) -> tuple[str, ...]:
        return tuple(data.regions)

    def baselines(self) -> Mapping[str, Callable[..., Any]]:
        return {name: (lambda config, _name=name: make_supply_baseline(_name)) for name in SUPPLY_BASELINES}

    # --- governance: the view the Planner/Auditor layer and the LLM agent read (tasks/governance_view.py)
    def governance_view(self, config: Any = None) -> SupplyGovernanceView:
        """The market as the governance layer sees it (docs/tasks/supply_chain.md#governance)."""
        return SupplyGovernanceView.from_config(config)

    # --- end governance


#: The supply-chain task (registered as ``supply-chain`` in :mod:`solarchain_eval.tasks.registry`).
SUPPLY_TASK = SupplyChainTask()
