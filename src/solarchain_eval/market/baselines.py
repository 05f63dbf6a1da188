"""Static, Random and Myopic baselines (docs/environment.md#baseline-policies)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..config import MarketConfig
from .actions import ActionCodec
from .observation import OBS_GAP, OBS_LIQUIDITY, OBS_VIOLATION


@dataclass
class StaticPolicy:
    """The configured static action (0.25, 0.75, 0.02) every hour, encoded once."""

    market: MarketConfig = field(default_factory=MarketConfig)
    name: str = "static"
    action_mode: str = "continuous"
    stateless = True  # episodes may run concurrently and in any order (see experiments/inflight.py)

    def __post_init__(self) -> None:
        m = self.market
        self._action = ActionCodec.from_config(m).encode(
            m.static_reward_ratio, m.static_liquidity_ratio, m.static_burn_rate
        )
        self._action.setflags(write=False)

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> np.ndarray:
        return self._action


@dataclass
class RandomPolicy:
    """Uniform actions from a generator seeded once per run with the run seed."""

    name: str = "random"
    action_mode: str = "continuous"

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(0)

    def begin_run(self, run_seed: int) -> None:
        self._rng = np.random.default_rng(run_seed)

    def act(self, observation: np.ndarray) -> np.ndarray:
        return self._rng.random(3, dtype=np.float32)


@dataclass
class MyopicPolicy:
    """One-step greedy rule on the observed supply gap, liquidity and violation rate.

    α = 0.18 if gap < -0.1 else 0.36; ℓ = 0.92 if L < 0.25 or gap < -0.1 else 0.48;
    b = 0.16 if ν > 0 or gap < -0.2 else 0.04.
    """

    market: MarketConfig = field(default_factory=MarketConfig)
    name: str = "myopic"
    action_mode: str = "continuous"
    stateless = True  # the action depends on the observation only

    def __post_init__(self) -> None:
        codec = ActionCodec.from_config(self.market)
        self._cache: dict[tuple[float, float, float], np.ndarray] = {}
        for alpha in (0.18, 0.36):
            for ell in (0.92, 0.48):
                for burn in (0.16, 0.04):
                    action = codec.encode(alpha, ell, burn)
                    action.setflags(write=False)
                    self._cache[(alpha, ell, burn)] = action

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> np.ndarray:
        gap = float(observation[OBS_GAP])
        liquidity = float(observation[OBS_LIQUIDITY])
        violation = float(observation[OBS_VIOLATION])
        alpha = 0.18 if gap < -0.1 else 0.36
        ell = 0.92 if liquidity < 0.25 or gap < -0.1 else 0.48
        burn = 0.16 if violation > 0.0 or gap < -0.2 else 0.04
        return self._cache[(alpha, ell, burn)]


BASELINES = ("static", "random", "myopic")


def make_baseline(name: str, market: MarketConfig | None = None) -> StaticPolicy | RandomPolicy | MyopicPolicy:
    market = market or MarketConfig()
    key = name.strip().lower()
    if key == "static":
        return StaticPolicy(market)
    if key == "random":
        return RandomPolicy()
    if key == "myopic":
        return MyopicPolicy(market)
    raise ValueError(f"unknown baseline policy '{name}' (choose from {', '.join(BASELINES)})")
