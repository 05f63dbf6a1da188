"""Agents of tests/test_isolated_agent.py, in a module of their own so that the isolated agent's
process imports only this (and numpy), not the test module with pytest, pandas and the CLI."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.market.baselines import make_baseline


def static_action() -> list[float]:
    return [float(v) for v in np.asarray(make_baseline("static", BenchmarkConfig().market).act(np.zeros(1)))]


class Honest:
    """Static's action from a user agent, with every hook: a run seed's generator, state through episodes."""

    name = "honest"

    def __init__(self) -> None:
        self.action = np.asarray(static_action(), dtype=np.float32)
        self.rng: np.random.Generator | None = None
        self.reward = 0.0
        self.steps = 0

    def begin_run(self, run_seed: int) -> None:
        self.rng = np.random.default_rng(run_seed)

    def begin_episode(self, *, episode: int, run_seed: int, episode_seed: int, start_hour: int) -> None:
        self.steps = 0

    def observe(self, info: dict) -> None:
        self.reward += float(info["reward"])
        self.steps += 1

    def act(self, observation: np.ndarray) -> np.ndarray:
        assert self.rng is not None
        jitter = self.rng.uniform(-0.05, 0.05, size=3).astype(np.float32)
        memory = np.float32(0.01 * np.tanh(self.reward))  # what observe() saw moves the action
        return np.clip(self.action + jitter + memory + np.float32(1e-3) * observation[:3], 0, 1)

    def end_episode(self) -> dict:
        return {"steps_seen": self.steps, "reward_seen": np.float64(self.reward)}


def constant(observation: np.ndarray) -> list[float]:
    return static_action()


class Counter:
    name = "counter"

    def __init__(self) -> None:
        self.count = 0

    def act(self, observation):
        self.count += 1
        return [self.count / 100, 0.5, 0.5]


class RaisesAtStep:
    name = "raises"

    def __init__(self, step: int, error: str = "value") -> None:
        self.step, self.error, self.count = step, error, 0

    def act(self, observation):
        self.count += 1
        if self.count == self.step:
            if self.error == "exit":
                os._exit(3)
            if self.error == "shape":
                return [0.5, 0.5]
            if self.error == "object":
                return [object()] * 3  # the right shape, but no data
            raise ValueError("no market\nfor me")
        return [0.5, 0.5, 0.5]


class FailingObserve(RaisesAtStep):
    def observe(self, info):
        raise KeyError("reward")


class Evil:
    """Unpickling this runs code: the agent's process must never get it unpickled here."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (Path(self.path).touch, ())


class ReturnsEvil:
    name = "evil"

    def __init__(self, path: str) -> None:
        self.path = path

    def act(self, observation):
        return [0.5, 0.5, 0.5]

    def end_episode(self):
        return {"payload": Evil(self.path)}


class Echo:
    """Answers the first three observation values as its action, in the observation's own dtype."""

    name = "echo"

    def act(self, observation):
        return observation[:3].copy()


class BadAt:
    """Acts well until episode 1, step 3, then returns ``bad``."""

    name = "bad"

    def __init__(self, bad) -> None:
        self.bad, self.episode, self.step = bad, 0, 0

    def begin_episode(self, *, episode, **_context) -> None:
        self.episode, self.step = episode, 0

    def act(self, observation):
        self.step += 1
        return self.bad if (self.episode, self.step) == (1, 3) else np.float32([0.3, 0.7, 0.05])
