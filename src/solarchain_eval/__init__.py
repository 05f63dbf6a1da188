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

from .tasks.registry import BUILTIN_ENV_REGISTRATIONS, load_target, register_builtin_envs

register_builtin_envs()  # SolarChainEval-v0 and SupplyChainEval-v0 (the registry names their modules)

__all__ = ["Evaluation", "__version__", "evaluate", "register_envs"]


def __getattr__(name: str):
    # The evaluation API loads on first use, so ``import solarchain_eval`` stays light.
    if name in ("evaluate", "Evaluation"):
        from .evaluation import evaluate as module

        return getattr(module, name)
    if name == "register_envs":  # the solar market's registration, kept public under its old name
        return load_target(BUILTIN_ENV_REGISTRATIONS[0])
    raise AttributeError(f"module 'solarchain_eval' has no attribute {name!r}")
