"""Gymnasium registration of ``SupplyChainEval-v0`` (single and native vector entry points)."""

from __future__ import annotations

import gymnasium as gym

SUPPLY_ENV_ID = "SupplyChainEval-v0"


def register_supply_envs() -> None:
    if SUPPLY_ENV_ID in gym.registry:
        return
    gym.register(
        id=SUPPLY_ENV_ID,
        entry_point="solarchain_eval.supply.env:SupplyChainEnv",
        vector_entry_point="solarchain_eval.supply.vector:SupplyChainVectorEnv",
        disable_env_checker=False,
    )
