"""SolarChain-Eval: a physics-constrained benchmark for trustworthy economic agents.

Importing the package registers ``SolarChainEval-v0`` with Gymnasium::

    import gymnasium as gym
    import solarchain_eval  # noqa: F401  (registers the environment)

    env = gym.make("SolarChainEval-v0", data_dir="path/to/dataset")

and gives the door for any agent, :func:`solarchain_eval.evaluate`::

    result = solarchain_eval.evaluate(my_agent)  # the paper's protocol, beside nothing
    result = solarchain_eval.evaluate([my_agent, "static", "myopic"], episodes=5)
"""

from __future__ import annotations

__version__ = "0.2.0"

from .envs.registration import register_envs
from .supply.registration import register_supply_envs

register_envs()
register_supply_envs()

__all__ = ["Evaluation", "__version__", "evaluate", "register_envs"]


def __getattr__(name: str):
    # The evaluation API loads on first use, so ``import solarchain_eval`` stays light.
    if name in ("evaluate", "Evaluation"):
        from .evaluation import evaluate as module

        return getattr(module, name)
    raise AttributeError(f"module 'solarchain_eval' has no attribute {name!r}")
