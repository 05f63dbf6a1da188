"""SolarChain-Eval: a physics-constrained benchmark for trustworthy economic agents.

Importing the package registers ``SolarChainEval-v0`` with Gymnasium::

    import gymnasium as gym
    import solarchain_eval  # noqa: F401  (registers the environment)

    env = gym.make("SolarChainEval-v0", data_dir="path/to/dataset")
"""

from __future__ import annotations

__version__ = "0.1.0"

from .envs.registration import register_envs

register_envs()

__all__ = ["__version__", "register_envs"]
