"""Learned policies from JAX-backend checkpoints (``train --backend jax``), beside the SB3 ones.

A JAX training directory holds ``jax_model.msgpack`` (the acting network's parameters) and
``train_config.json`` (``identity.algo``, ``identity.backend`` = "jax" and the rejax settings).
``ppo``, ``sac`` and ``dqn`` find such a checkpoint through the same ``models`` mapping as the
SB3 models (``evaluate --models``):

- ``{name: PATH}``: PATH is a ``.msgpack`` file or a directory holding ``jax_model.msgpack``;
- ``{"*": DIR}``: ``DIR/<name>/jax_model.msgpack``, or ``DIR/jax_model.msgpack`` when
  ``DIR/train_config.json`` says it is a ``<name>`` model.

Where no JAX checkpoint is found, the SB3 factory resolves the name as before; where ``DIR``
holds both an SB3 model and a JAX checkpoint for the same name, the choice is refused (pass
``--models NAME=PATH``). JAX is imported only when a checkpoint is loaded.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BenchmarkConfig
from ..tasks.registry import get_task
from .checkpoints import ACTION_MODES, TRAIN_CONFIG_FILE, read_train_config, trained_algo

JAX_MODEL_FILE = "jax_model.msgpack"


def jax_model_path(name: str, models: dict[str, Path]) -> Path | None:
    """The JAX checkpoint for policy ``name`` in ``models``, or None (see the module docstring)."""
    explicit = models.get(name)
    if explicit is not None:
        path = Path(explicit)
        if path.is_file() and path.suffix == ".msgpack":
            return path
        if path.is_dir() and (path / JAX_MODEL_FILE).is_file():
            return path / JAX_MODEL_FILE
        return None  # an explicit non-JAX path is the SB3 factory's to resolve
    shared = models.get("*")
    if shared is None:
        return None
    root = Path(shared)
    if (root / name / JAX_MODEL_FILE).is_file():
        return root / name / JAX_MODEL_FILE
    if (root / JAX_MODEL_FILE).is_file() and trained_algo(root) == name:
        return root / JAX_MODEL_FILE
    return None


@dataclass
class JaxPolicy:
    """A rejax-trained network acting deterministically (the same choice as SB3's ``predict``).

    Parameters
    ----------
    name : str
        "ppo", "sac" or "dqn".
    model_path : path
        ``jax_model.msgpack``; its ``train_config.json`` must sit beside it.
    config : BenchmarkConfig
        Gives the size of the discrete action grid.
    """

    name: str
    model_path: Path
    config: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    action_mode: str = ""
    #: The task whose env the network acts in (None: the solar market).
    task: str | None = None

    def __post_init__(self) -> None:
        self.action_mode = ACTION_MODES[self.name]
        self.model_path = Path(self.model_path)
        meta = read_train_config(self.model_path.parent)
        if meta is None or not isinstance(meta.get("rejax"), dict):
            raise ValueError(
                f"{self.model_path}: no readable {TRAIN_CONFIG_FILE} with the rejax settings beside it "
                "(a JAX checkpoint needs the directory written by train --backend jax)"
            )
        algo = (meta.get("identity") or {}).get("algo")
        if algo != self.name:
            raise ValueError(f"{self.model_path} holds a {algo} model, not {self.name}")
        try:
            from .jax_network import JaxActor
        except ImportError as error:
            raise ValueError(f"{self.model_path} is a JAX checkpoint: {error}") from None
        n_levers = len(get_task(self.task).levers)
        self.actor = JaxActor(
            self.name,
            self.model_path,
            meta["rejax"],
            self.action_mode,
            self.config.discrete_levels**n_levers,
            self.task,
        )

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> Any:
        return self.actor.act(observation)


def register_jax_policies(registry: dict[str, Callable[[BenchmarkConfig, dict[str, Path]], Any]]) -> None:
    """Let the ``ppo``, ``sac`` and ``dqn`` factories also load JAX checkpoints (call after the SB3 ones)."""
    from .sb3 import model_candidates

    for name in ACTION_MODES:
        fallback = registry[name]

        def build(
            config: BenchmarkConfig,
            models: dict[str, Path],
            task: str | None = None,
            name: str = name,
            fallback=fallback,
        ) -> Any:
            path = jax_model_path(name, models)
            if path is None:
                return fallback(config, models, task=task)
            if name not in models:
                sb3 = [p for p in model_candidates(name, models) if p.is_file()]
                if sb3:
                    raise ValueError(
                        f"policy '{name}': {models['*']} holds both an SB3 model ({sb3[0]}) and a JAX "
                        f"checkpoint ({path}); choose one with --models {name}=PATH"
                    )
            return JaxPolicy(name, path, config, task=task)

        build.__name__ = f"make_{name}_policy"
        build.takes_task = True  # type: ignore[attr-defined]
        registry[name] = build
