"""Stable-Baselines3 conventions shared by the trainer and the policy adapter.

The algorithm names, the action mode each acts in, the files of a training directory and the
SB3 class of a name. :mod:`solarchain_eval.training` (which writes training directories) and
:mod:`solarchain_eval.policies.sb3` (which loads them) both import this module and not each
other. Stable-Baselines3 itself is imported only by :func:`algorithm_class`.
"""

from __future__ import annotations

from .option_errors import NamesOptions

ALGOS = ("ppo", "sac", "dqn")
#: Algorithm -> the env action mode it trains and acts in.
ACTION_MODES = {"ppo": "continuous", "sac": "continuous", "dqn": "discrete"}
#: Everything ``train`` accepts: the paper's algorithms plus the opt-in PPO-Lagrangian
#: (docs/training.md#ppo-lagrangian; its model.zip is a plain PPO model).
TRAINABLE_ACTION_MODES = {**ACTION_MODES, "ppo-lag": "continuous"}
TRAINABLE_ALGOS = tuple(TRAINABLE_ACTION_MODES)
#: Trainable algorithms a grid runs only when asked for (``paper --extra-policies``, a sweep).
OPT_IN_ALGOS = tuple(a for a in TRAINABLE_ALGOS if a not in ALGOS)
MODEL_FILE = "model.zip"
TRAIN_CONFIG_FILE = "train_config.json"


class TrainingError(NamesOptions, ValueError):
    """A training request that cannot be carried out as given (reported without a traceback)."""


def check_algo(algo: str) -> str:
    """``algo`` normalised (stripped, lower case); a :class:`TrainingError` if it is not in :data:`TRAINABLE_ALGOS`."""
    key = algo.strip().lower()
    if key not in TRAINABLE_ALGOS:
        raise TrainingError(f"unknown algorithm '{algo}' (choose from {', '.join(TRAINABLE_ALGOS)})")
    return key


def algorithm_class(algo: str) -> type:
    """The Stable-Baselines3 class of ``algo`` (imports SB3)."""
    from stable_baselines3 import DQN, PPO, SAC

    return {"ppo": PPO, "sac": SAC, "dqn": DQN, "ppo-lag": PPO}[check_algo(algo)]
