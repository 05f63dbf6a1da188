"""The policy interface used by the evaluation runner."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Policy(Protocol):
    """A policy maps observations to actions in the env's action space.

    ``action_mode`` says which env it needs (``"continuous"`` or ``"discrete"``).
    ``begin_run`` is called once per run seed before its first episode (the Random baseline
    seeds its generator there); ``act`` must be deterministic given the policy's state.
    A policy may also declare ``stateless = True``: its action depends on the observation only
    and ``act`` may be called from several threads, so its episodes can run concurrently
    (``evaluate --llm-concurrency``); without it, a run's episodes run in order.
    """

    name: str
    action_mode: str

    def begin_run(self, run_seed: int) -> None: ...

    def act(self, observation: np.ndarray) -> Any: ...
