"""The market's observation and action spaces as Gymnasium spaces: one definition for every env.

The single env, the vector env, the trainers' stand-in env and the JAX env's gymnax spaces all
take their shapes and bounds from here.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from .observation import OBS_LIMIT, OBSERVATION_SHAPE

#: (reward ratio α, liquidity ratio ℓ, burn rate b), each a unit-interval control.
ACTION_SHAPE = (3,)
#: Bounds of the continuous action box (decoded into market units by the action codec).
ACTION_LOW, ACTION_HIGH = 0.0, 1.0


def observation_space() -> spaces.Box:
    """``Box(-10, 10, (12,), float32)``: the features of :data:`~.observation.OBSERVATION_NAMES`."""
    return spaces.Box(-OBS_LIMIT, OBS_LIMIT, shape=OBSERVATION_SHAPE, dtype=np.float32)


def n_discrete_actions(levels: int) -> int:
    """Size of the discrete grid with ``levels`` values per action component (5 → 125)."""
    return levels ** ACTION_SHAPE[0]


def action_space(action_mode: str, discrete_levels: int) -> spaces.Space:
    """``Box(0, 1, (3,), float32)`` (continuous) or ``Discrete(levels**3)`` (discrete)."""
    if action_mode == "discrete":
        return spaces.Discrete(n_discrete_actions(discrete_levels))
    return spaces.Box(ACTION_LOW, ACTION_HIGH, shape=ACTION_SHAPE, dtype=np.float32)
