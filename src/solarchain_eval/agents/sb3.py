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

A model file is loaded without running code it names (:func:`safe_custom_objects`): every
pickled entry of its ``data`` is rebuilt by :func:`~.safe_pickle.safe_loads` (which refuses
any function or foreign class) or replaced by a stand-in, and every tensor file is read with
``torch.load(weights_only=True)`` first. VecNormalize statistics (a pickle) are read the same
way (docs/security.md#learned-models).
"""

from __future__ import annotations

import base64
import io
import json
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..common.errors import InputDataError, NamesOptions, RefusedError
from ..config import BenchmarkConfig
from ..tasks.base import observation_names_of
from ..tasks.registry import get_task
from .checkpoints import MODEL_FILE, TRAINABLE_ACTION_MODES, algorithm_class, trained_algo
from .safe_pickle import safe_loads

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


class ModelNotFoundError(NamesOptions, InputDataError, FileNotFoundError):
    """No trained model for a learned policy (the message lists where it looked)."""


#: Entries of a model's ``data`` that acting never reads or that SB3 rebuilds from the rest; a
#: refused pickle there is replaced (schedules by a constant one, the others by None).
_SCHEDULES = ("learning_rate", "lr_schedule", "clip_range", "clip_range_vf", "exploration_schedule")
#: Entries a model cannot act without: a refused pickle there refuses the model.
_NEEDED = ("observation_space", "action_space", "policy_class", "policy_kwargs")


class UnsafeModel(RefusedError, ValueError):
    """A model file whose pickled parts name code a model never needs (refused, nothing run)."""


def _zero_schedule(_progress_remaining: float) -> float:
    return 0.0  # stands in for a training schedule: acting never reads it


def safe_custom_objects(path: Path) -> dict[str, Any]:
    """SB3's ``custom_objects`` for ``path``: every pickled entry of its ``data``, rebuilt safely or replaced.

    Every ``.pth`` member is first read with ``torch.load(weights_only=True)`` (tensors and
    plain containers only), so SB3's own read of it cannot run code either.

    Raises
    ------
    UnsafeModel
        A needed entry (:data:`_NEEDED`) or a tensor file names code; nothing was run.
    """
    import torch

    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        for member in (n for n in names if n.endswith(".pth")):
            try:
                torch.load(io.BytesIO(archive.read(member)), map_location="cpu", weights_only=True)
            except Exception as error:  # torch raises UnpicklingError, RuntimeError, ... for a foreign pickle
                why = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
                raise UnsafeModel(f"{member} holds more than tensors, refused without running it ({why})") from None
        data = json.loads(archive.read("data")) if "data" in names else {}
    custom: dict[str, Any] = {}
    for key, item in data.items() if isinstance(data, dict) else ():
        if not (isinstance(item, dict) and ":serialized:" in item):
            continue
        try:
            custom[key] = safe_loads(base64.b64decode(str(item[":serialized:"])))
        except Exception as error:  # UnsafePickle (a refused name), or a damaged pickle
            if key in _NEEDED:
                raise UnsafeModel(f"its pickled entry {key!r} {error}; refused without running it") from None
            custom[key] = _zero_schedule if key in _SCHEDULES else None
    return custom


def _load_safely(cls: type, path: Path, label: str) -> Any:
    """``cls.load(path)`` on the CPU with every pickled entry replaced (:func:`safe_custom_objects`)."""
    try:
        return cls.load(path, device="cpu", custom_objects=safe_custom_objects(path))
    except UnsafeModel as error:
        raise ValueError(f"cannot load {path} as a {label} model: {error}") from None
    except Exception as error:  # SB3 raises many kinds for a wrong or damaged file
        raise ValueError(f"cannot load {path} as a {label} model: {type(error).__name__}: {error}") from None


def load_model(name: str, path: Path) -> Any:
    """Load ``path`` with the SB3 class of ``name`` on the CPU, running no pickled code; errors name the file."""
    return _load_safely(algorithm_class(name), Path(path), name.upper())


def check_model_spaces(model: Any, action_mode: str, config: Any, source: Path | str, task: str | None = None) -> None:
    """Refuse a model whose observation or action space does not fit the env of ``task`` (default:
    the solar market; errors name ``source``)."""
    market = get_task(task)
    names = observation_names_of(market)
    obs_shape = tuple(model.observation_space.shape or ())
    if names is not None and obs_shape != (len(names),):
        raise ValueError(f"{source}: the model observes shape {obs_shape}, the env gives {(len(names),)}")
    space = model.action_space
    n_levers = len(market.levers)
    if action_mode == "discrete":
        expected = int(config.discrete_levels) ** n_levers
        if getattr(space, "n", None) != expected:
            raise ValueError(f"{source}: the model has {getattr(space, 'n', space)} actions, the env {expected}")
    elif tuple(space.shape or ()) != (n_levers,):
        raise ValueError(f"{source}: the model's actions have shape {space.shape}, the env expects ({n_levers},)")


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


def load_sb3_model(algo: str, path: Path | str, config: Any, task: str | None = None) -> Any:
    """Load a model of any SB3 / sb3-contrib algorithm on the CPU and check it fits the env of ``task``."""
    path = Path(path)
    cls = sb3_algorithm(algo)
    if not path.is_file():
        raise ValueError(f"no model file {path}")
    model = _load_safely(cls, path, cls.__name__)
    mode = "discrete" if getattr(model.action_space, "n", None) is not None else "continuous"
    check_model_spaces(model, mode, config, path, task)
    return model


def load_vecnormalize(path: Path | str) -> Any:
    """VecNormalize statistics saved by ``VecNormalize.save`` (observations normalised, not updated),
    unpickled by :func:`~.safe_pickle.safe_loads` (a pickle naming anything else is refused, not run)."""
    from stable_baselines3.common.vec_env import VecNormalize

    path = Path(path)
    try:
        stats = safe_loads(path.read_bytes())
    except Exception as error:  # a missing, truncated, foreign or unsafe file
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
    #: The task whose env the model acts in (None: the solar market); its spaces are checked.
    task: str | None = None
    stateless = True  # deterministic predict, no recurrent state: episodes may run concurrently

    def __post_init__(self) -> None:
        self.action_mode = LEARNED_POLICIES[self.name]
        self.model = load_model(self.name, self.model_path)
        self._check_spaces()

    def _check_spaces(self) -> None:
        check_model_spaces(self.model, self.action_mode, self.config, self.model_path, self.task)

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> Any:
        action, _ = self.model.predict(observation, deterministic=True)
        return action


def _factory(name: str) -> Callable[[BenchmarkConfig, dict[str, Path]], SB3Policy]:
    def build(config: BenchmarkConfig, models: dict[str, Path], task: str | None = None) -> SB3Policy:
        return SB3Policy(name, resolve_model_path(name, models), config, task=task)

    build.__name__ = f"make_{name}_policy"
    build.takes_task = True  # type: ignore[attr-defined]  # make_policy passes the evaluated task
    return build


def register_learned_policies(registry: dict[str, Callable[[BenchmarkConfig, dict[str, Path]], Any]]) -> None:
    """Add the ``ppo``, ``sac`` and ``dqn`` factories to a policy registry."""
    for name in LEARNED_POLICIES:
        registry.setdefault(name, _factory(name))
