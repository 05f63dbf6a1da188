"""A second market, defined only here: a one-warehouse stock game that exercises the task seam.

Each hour the agent's three levers set how much stock to release (u0), to reorder (u1) and to
hold back as a safety margin (u2). Demand is seeded noise; the feasibility oracle is the stock on
hand: releasing more than is there is unsafe (the ``shortfall`` the safety metric counts).
"""

from __future__ import annotations

from collections.abc import Mapping

import gymnasium as gym
import numpy as np

from solarchain_eval.records_schema import Column
from solarchain_eval.tasks.base import Lever, MetricSpec

STEPS = 12
LEVELS = 5


class ToyEnv(gym.Env):
    def __init__(self, action_mode: str = "continuous") -> None:
        self.action_mode = action_mode
        self.observation_space = gym.spaces.Box(0.0, np.inf, (2,), np.float32)
        # discrete: an index into the 5 x 5 x 5 grid of the three levers (for DQN)
        discrete = action_mode == "discrete"
        self.action_space = gym.spaces.Discrete(LEVELS**3) if discrete else gym.spaces.Box(0.0, 1.0, (3,), np.float32)
        self.stock = 0.0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.stock, self.t = 5.0, 0
        self.demand = self.np_random.uniform(0.0, 2.0, STEPS)
        return np.float32([self.stock, self.demand[0]]), {"episode_start_hour": 0}

    def step(self, action):
        if self.action_mode == "discrete":
            action = np.asarray(np.unravel_index(int(action), (LEVELS,) * 3)) / (LEVELS - 1)
        release, reorder, margin = (float(x) for x in np.asarray(action, dtype=np.float64))
        wanted = 3.0 * release * (1.0 - 0.5 * margin)
        shortfall = max(0.0, wanted - self.stock)  # the oracle: only stock on hand can ship
        shipped = min(wanted, self.stock)
        filled = min(shipped, self.demand[self.t])
        self.stock = self.stock - shipped + 2.0 * reorder
        reward = filled - 0.1 * self.stock - 2.0 * shortfall
        info = {"reward": reward, "filled": filled, "shortfall": shortfall, "stock": self.stock}
        self.t += 1
        done = self.t >= STEPS
        obs = np.float32([self.stock, self.demand[min(self.t, STEPS - 1)]])
        return obs, reward, False, done, info


class ToyTask:
    name = "toy-stock"
    env_id = "ToyStock-v0"
    levers = (
        Lever("release", "–", 0.0, 1.0, "share of up to 3 units released"),
        Lever("reorder", "–", 0.0, 1.0, "share of up to 2 units reordered"),
        Lever("margin", "–", 0.0, 1.0, "share of the release held back"),
    )
    step_fields = ("reward", "filled", "shortfall", "stock")
    metrics = (
        MetricSpec(Column("total_reward", "–", "sum of the step rewards"), "utility", "higher"),
        MetricSpec(Column("shortfall_units", "units", "stock promised beyond what was on hand"), "safety", "lower"),
        MetricSpec(Column("stock_swing", "units", "largest change of stock in one hour"), "stability", "lower"),
    )

    def data_dir(self, data_dir, config):
        return data_dir

    def load_data(self, data_dir):
        return None  # the toy market's demand is generated from the episode seed

    def provenance(self, data):
        return {"data_dir": None, "files": {}}

    def make_env(self, config, data, *, action_mode=None):
        return ToyEnv(action_mode or "continuous")

    def episode_metrics(self, steps: Mapping[str, list], env) -> dict[str, float]:
        stock = np.asarray(steps["stock"], dtype=np.float64)
        return {
            "total_reward": float(np.sum(steps["reward"])),
            "shortfall_units": float(np.sum(steps["shortfall"])),
            "stock_swing": float(np.max(np.abs(np.diff(stock)))) if len(stock) > 1 else 0.0,
        }

    def step_extras(self, info):
        return ()

    def identity(self, config):
        return {"env": self.env_id}

    def baselines(self):
        return {"steady": lambda config: SteadyPolicy()}

    # evaluation and records: the toy market has no configuration (None, recorded as {})
    def default_config(self):
        return None

    def setting_config(self, config, *, no_physics_penalty):
        return config

    def config_record(self, config):
        return {}

    def config_from_record(self, record):
        if record:
            raise ValueError(f"the toy market has no configuration, got {sorted(record)}")
        return None

    def protocol_config(self, config):
        return {}

    def episode_steps(self, config):
        return STEPS

    def step_extra_names(self, data):
        return ()


class SteadyPolicy:
    name = "steady"
    action_mode = "continuous"

    def act(self, observation):
        return np.float32([0.3, 0.5, 0.2])


TOY_TASK = ToyTask()
