"""Learned policies: trained Stable-Baselines3 models acting deterministically.

``ppo`` and ``sac`` act on the continuous env, ``dqn`` on the 125-point discrete grid. Each is
built from a model file found through the ``models`` mapping that ``make_policy`` receives
(``evaluate --models``):

- ``{name: PATH}``: PATH is the model file, or a directory holding ``model.zip`` (a training
  directory) or ``<name>.zip``;
- ``{"*": DIR}``: DIR is searched for, in order, ``DIR/<name>.zip``, ``DIR/<name>/model.zip``
  (``train --out DIR/<name>``), ``DIR/model.zip`` when ``DIR/train_config.json`` says it is a
  ``<name>`` model, and the original release's ``DIR/models/<name>/<name>_model.zip``.

An explicit ``{name: PATH}`` wins over ``{"*": DIR}``. Stable-Baselines3 is imported only when a
model is loaded.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..common.errors import NamesOptions
from ..config import BenchmarkConfig
from ..market.observation import OBSERVATION_SHAPE
from .checkpoints import MODEL_FILE, TRAINABLE_ACTION_MODES, algorithm_class, trained_algo

#: Learned policy name -> the env action mode it acts in.
LEARNED_POLICIES = dict(TRAINABLE_ACTION_MODES)  # ppo-lag's model is a plain PPO model


def parse_models(items: list[str]) -> dict[str, Path]:
    """The ``models`` mapping from ``DIR`` and ``NAME=PATH`` items (the ``--models`` values): a bare
    directory is ``{"*": DIR}`` (the last one wins), ``NAME=PATH`` is ``{name: PATH}``."""
    models: dict[str, Path] = {}
    for item in items:
        if "=" in item:
            name, path = item.split("=", 1)
            models[name.strip().lower()] = Path(path)
        else:
            models["*"] = Path(item)
    return models


def model_candidates(name: str, models: dict[str, Path]) -> list[Path]:
    """The paths searched for policy ``name``'s model, in order (see the module docstring)."""
    candidates: list[Path] = []
    explicit = models.get(name)
    if explicit is not None:
        explicit = Path(explicit)
        if explicit.is_dir():
            candidates += [explicit / MODEL_FILE, explicit / f"{name}.zip"]
        else:
            candidates.append(explicit)
    shared = models.get("*")
    if shared is not None:
        root = Path(shared)
        candidates += [root / f"{name}.zip", root / name / MODEL_FILE]
        if trained_algo(root) in (None, name):
            candidates.append(root / MODEL_FILE)
        candidates.append(root / "models" / name / f"{name}_model.zip")
    return candidates


def resolve_model_path(name: str, models: dict[str, Path]) -> Path:
    """The first existing candidate for ``name``.

    Raises
    ------
    FileNotFoundError
        No model was given, or none of the candidates exists (the message lists them).
    """
    if not models:
        raise ModelNotFoundError.about(
            "policy '{name}' needs a trained model: pass {opt_models} DIR or {opt_models} {name}=PATH "
            "(train one with: solarchain-eval train --algo {name} --out DIR/{name})",
            name=name,
        )
    candidates = model_candidates(name, models)
    for path in candidates:
        if path.is_file():
            return path
    looked = ", ".join(str(p) for p in candidates) or "(no path given for it)"
    raise ModelNotFoundError.about(
        "no trained model for policy '{name}': looked for {looked} "
        "(pass {opt_models} {name}=PATH, or train one with: solarchain-eval train --algo {name})",
        name=name,
        looked=looked,
    )


class ModelNotFoundError(NamesOptions, FileNotFoundError):
    """No trained model for a learned policy (the message lists where it looked)."""


def load_model(name: str, path: Path) -> Any:
    """Load ``path`` with the SB3 class of ``name`` on the CPU; errors name the file."""
    try:
        return algorithm_class(name).load(path, device="cpu")
    except Exception as error:  # SB3 raises many kinds for a wrong or damaged file
        raise ValueError(f"cannot load {path} as a {name.upper()} model: {type(error).__name__}: {error}") from None


def check_model_spaces(model: Any, action_mode: str, config: BenchmarkConfig, source: Path | str) -> None:
    """Refuse a model whose observation or action space does not fit the env (errors name ``source``)."""
    obs_shape = tuple(model.observation_space.shape or ())
    if obs_shape != OBSERVATION_SHAPE:
        raise ValueError(f"{source}: the model observes shape {obs_shape}, the env gives {OBSERVATION_SHAPE}")
    space = model.action_space
    if action_mode == "discrete":
        expected = config.discrete_levels**3
        if getattr(space, "n", None) != expected:
            raise ValueError(f"{source}: the model has {getattr(space, 'n', space)} actions, the env {expected}")
    elif tuple(space.shape or ()) != (3,):
        raise ValueError(f"{source}: the model's actions have shape {space.shape}, the env expects (3,)")


def sb3_algorithm(algo: str) -> type:
    """The Stable-Baselines3 or sb3-contrib algorithm class named ``algo`` (any case: ``tqc``, ``TQC``)."""
    import stable_baselines3
    from stable_baselines3.common.base_class import BaseAlgorithm

    modules: list[Any] = [stable_baselines3]
    try:
        import sb3_contrib

        modules.append(sb3_contrib)
    except ImportError:  # sb3-contrib is a dependency, but a trimmed install may lack it
        pass
    found: dict[str, type] = {}
    for module in modules:
        for attr in getattr(module, "__all__", dir(module)):
            value = getattr(module, attr, None)
            if isinstance(value, type) and issubclass(value, BaseAlgorithm):
                found.setdefault(attr.lower(), value)
    cls = found.get(algo.strip().lower())
    if cls is None:
        raise ValueError(f"unknown SB3 algorithm {algo!r} (installed: {', '.join(sorted(found))})")
    return cls


def load_sb3_model(algo: str, path: Path | str, config: BenchmarkConfig) -> Any:
    """Load a model of any SB3 / sb3-contrib algorithm on the CPU and check it fits the env."""
    path = Path(path)
    cls = sb3_algorithm(algo)
    if not path.is_file():
        raise ValueError(f"no model file {path}")
    try:
        model = cls.load(path, device="cpu")
    except Exception as error:  # SB3 raises many kinds for a wrong or damaged file
        raise ValueError(f"cannot load {path} as a {cls.__name__} model: {type(error).__name__}: {error}") from None
    mode = "discrete" if getattr(model.action_space, "n", None) is not None else "continuous"
    check_model_spaces(model, mode, config, path)
    return model


def load_vecnormalize(path: Path | str) -> Any:
    """VecNormalize statistics saved by ``VecNormalize.save`` (observations normalised, not updated)."""
    import pickle

    from stable_baselines3.common.vec_env import VecNormalize

    path = Path(path)
    try:
        with path.open("rb") as handle:
            stats = pickle.load(handle)  # noqa: S301 - the user's own statistics file, as SB3 loads it
    except Exception as error:  # a missing, truncated or foreign file
        raise ValueError(f"cannot read VecNormalize statistics from {path}: {type(error).__name__}: {error}") from None
    if not isinstance(stats, VecNormalize):
        raise ValueError(f"{path} holds a {type(stats).__name__}, not VecNormalize statistics")
    stats.training = False
    return stats


@dataclass
class SB3Policy:
    """A trained model acting with ``model.predict(obs, deterministic=True)``.

    Parameters
    ----------
    name : str
        "ppo", "sac" or "dqn".
    model_path : path
    config : BenchmarkConfig
        Used to check that the model's spaces match the env it will act in.
    """

    name: str
    model_path: Path
    config: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    action_mode: str = ""
    stateless = True  # deterministic predict, no recurrent state: episodes may run concurrently

    def __post_init__(self) -> None:
        self.action_mode = LEARNED_POLICIES[self.name]
        self.model = load_model(self.name, self.model_path)
        self._check_spaces()

    def _check_spaces(self) -> None:
        check_model_spaces(self.model, self.action_mode, self.config, self.model_path)

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> Any:
        action, _ = self.model.predict(observation, deterministic=True)
        return action


def _factory(name: str) -> Callable[[BenchmarkConfig, dict[str, Path]], SB3Policy]:
    def build(config: BenchmarkConfig, models: dict[str, Path]) -> SB3Policy:
        return SB3Policy(name, resolve_model_path(name, models), config)

    build.__name__ = f"make_{name}_policy"
    return build


def register_learned_policies(registry: dict[str, Callable[[BenchmarkConfig, dict[str, Path]], Any]]) -> None:
    """Add the ``ppo``, ``sac`` and ``dqn`` factories to a policy registry."""
    for name in LEARNED_POLICIES:
        registry.setdefault(name, _factory(name))
