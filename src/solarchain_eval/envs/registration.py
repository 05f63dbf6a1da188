"""Gymnasium registration of ``SolarChainEval-v0`` (single and native vector entry points)."""

from __future__ import annotations

import gymnasium as gym

ENV_ID = "SolarChainEval-v0"


def register_envs() -> None:
    if ENV_ID in gym.registry:
        return
    gym.register(
        id=ENV_ID,
        entry_point="solarchain_eval.envs.env:SolarChainEnv",
        vector_entry_point="solarchain_eval.envs.vector:SolarChainVectorEnv",
        disable_env_checker=False,
    )
