"""What a training directory holds and how to read it: the one home of the trainers' and loaders' conventions.

The algorithm names, the action mode each acts in, the files of a training directory and the
SB3 class of a name. :mod:`solarchain_eval.training.sb3_trainer` (which writes training directories) and
:mod:`solarchain_eval.agents.sb3` (which loads them) both import this module and not each
other. Stable-Baselines3 itself is imported only by :func:`algorithm_class`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..common.errors import NamesOptions, OptionsError

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


class TrainingError(NamesOptions, OptionsError, ValueError):
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


def read_training_json(path: Path) -> dict[str, Any] | None:
    """A JSON file of a training directory (``train_config.json``, ``train_metadata.json``).

    None when the file is absent; a :class:`TrainingError` naming the file when it cannot be read.
    """
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except ValueError as error:
        raise TrainingError(f"{path} is not valid JSON ({error}); remove the directory to retrain") from None
    except OSError as error:
        raise TrainingError(f"{path} cannot be read ({error}); remove the directory to retrain") from None


def read_train_config(directory: Path) -> dict[str, Any] | None:
    """``DIR/train_config.json``, or None when it is absent or unreadable (a loader then looks elsewhere)."""
    try:
        return read_training_json(Path(directory) / TRAIN_CONFIG_FILE)
    except TrainingError:
        return None


def trained_algo(directory: Path) -> str | None:
    """The algorithm ``DIR/train_config.json`` says its model was trained with, or None."""
    identity = (read_train_config(directory) or {}).get("identity")
    algo = identity.get("algo") if isinstance(identity, dict) else None
    return algo if isinstance(algo, str) else None
