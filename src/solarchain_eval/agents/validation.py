"""What a user's agent hands back, checked: its actions and the dict its ``end_episode`` returns.

One rule for every door a user's agent comes through (a Python object or function, a
``file.py:Class``, a plugin, HTTP): an action is taken exactly as returned or refused, never
repaired. A continuous action is three finite numbers in [0, 1]; a discrete action is one integer
index into the grid. NaN, ±inf, 1.5, ``"0.5"`` or a wrong shape is a one-line error (the caller
adds the agent, run seed, episode and step) instead of being mapped to 0 or clipped, which would
make the agent's results meaningless. The environment's own NaN/clip decoding is unchanged: the
benchmark's built-in policies and SB3 models (whose sampled actions the environment clips, as in
training) still go through it.

What ``end_episode`` returns becomes the agent's own columns of ``metrics.csv``, each named
``agent_<key>`` (:data:`~solarchain_eval.records_schema.AGENT_COLUMN_PREFIX`), so an agent can
record what it measured but can never write a metric, its own name or an episode key.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from ..records_schema import AGENT_COLUMN_PREFIX

#: The key of :class:`~solarchain_eval.evaluation.rollout.EpisodeResult` ``extras`` that holds a
#: user agent's checked ``end_episode`` columns (already prefixed).
AGENT_EXTRAS_KEY = "agent_columns"
MAX_AGENT_COLUMNS = 32
MAX_TEXT_CHARS = 200
_KEY = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,39}$")
_SHOWN_CHARS = 80


def shown(value: Any) -> str:
    """``repr(value)`` on one line, shortened."""
    text = " ".join(repr(value).split())
    return text if len(text) <= _SHOWN_CHARS else text[: _SHOWN_CHARS - 3] + "..."


def continuous_problem(action: Any, *, check_values: bool = True, check_range: bool = True) -> str | None:
    """Why ``action`` is not a continuous action (three finite numbers in [0, 1]), or None.

    ``check_values=False`` checks the shape only (the benchmark's own policies);
    ``check_range=False`` lets finite values outside [0, 1] through (SB3 models, whose actions
    the environment clips as it did in training).
    """
    if action is None:
        return "act() returned None; a continuous action is three numbers in [0, 1]"
    try:
        shape = np.shape(action)
        value = np.asarray(action)
    except (TypeError, ValueError):
        return f"act() returned {type(action).__name__}; a continuous action is three numbers in [0, 1]"
    if shape not in ((3,), (1, 3)):
        return f"act() returned an action of shape {shape}; a continuous action has shape (3,)"
    if not check_values:
        return None
    if value.dtype.kind not in "iuf":
        return f"act() returned {shown(action)}; a continuous action is three numbers in [0, 1], not {value.dtype.name}"
    flat = value.astype(np.float64).ravel()
    if np.isfinite(flat).all() and (not check_range or ((flat >= 0.0) & (flat <= 1.0)).all()):
        return None  # the common case, checked at once
    for i, component in enumerate(flat.tolist()):
        if not math.isfinite(component):
            return f"act() returned action[{i}]={component!r}, which is not finite; a continuous action is three numbers in [0, 1]"
        if check_range and not 0.0 <= component <= 1.0:
            return f"act() returned action[{i}]={component!r}, outside [0, 1]; the benchmark does not clip a user agent's action"
    return None


def discrete_problem(action: Any, n_actions: int) -> str | None:
    """Why ``action`` is not an index into a grid of ``n_actions`` actions, or None."""
    try:
        value = np.asarray(action)
    except (TypeError, ValueError):
        value = np.asarray(None)
    if value.size != 1 or not np.issubdtype(value.dtype, np.integer):
        return f"act() returned {shown(action)}; a discrete action is one integer index"
    index = int(value.ravel()[0])
    if not 0 <= index < n_actions:
        return f"act() returned the index {index}, outside 0..{n_actions - 1}"
    return None


def agent_columns(returned: Any) -> dict[str, Any]:
    """The ``metrics.csv`` columns of what ``end_episode`` returned: ``{"agent_<key>": value}``.

    Raises
    ------
    ValueError
        ``returned`` is neither None nor a dict of at most :data:`MAX_AGENT_COLUMNS` keys (letters,
        digits and ``_``, starting with a letter) whose values are finite numbers or strings of at
        most :data:`MAX_TEXT_CHARS` printable characters; the message is one line.
    """
    if returned is None:
        return {}
    if not isinstance(returned, dict):
        return _refuse(f"returned {type(returned).__name__} {shown(returned)}; return None or a dict")
    if len(returned) > MAX_AGENT_COLUMNS:
        return _refuse(f"returned {len(returned)} keys; at most {MAX_AGENT_COLUMNS} are recorded")
    columns: dict[str, Any] = {}
    for key, value in returned.items():
        if not isinstance(key, str) or not _KEY.match(key):
            return _refuse(f"key {shown(key)}: keys are letters, digits and _ (starting with a letter, at most 40)")
        columns[AGENT_COLUMN_PREFIX + key] = _column_value(key, value)
    return columns


def _column_value(key: str, value: Any) -> float | int | str:
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, int | np.integer):
        if not -(2**63) <= int(value) < 2**63:
            return _refuse(f"{key!r} is {int(value)}, beyond a 64-bit integer")
        return int(value)
    if isinstance(value, float | np.floating):
        if not math.isfinite(value):
            return _refuse(f"{key!r} is {float(value)!r}; numbers must be finite")
        return float(value)
    if isinstance(value, str):
        if len(value) > MAX_TEXT_CHARS or not value.isprintable():
            return _refuse(f"{key!r}: text must be one line of at most {MAX_TEXT_CHARS} printable characters")
        return value
    return _refuse(f"{key!r} is {type(value).__name__} {shown(value)}; values are finite numbers or short text")


def _refuse(problem: str) -> Any:
    raise ValueError(f"end_episode() {problem}")
