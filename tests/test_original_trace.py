"""Every env step of the original release's own trace, replayed here, is bit-equal.

``original_release_traces/`` (shared data, see its README) holds 4,800 steps per setting made by
the original release's unmodified env: 200 episodes reset with seeds 20260511 + k, half the
actions uniform in [0, 1), half grid points {0, .25, .5, .75, 1}^3 (479 of them with u1 = 1, where
the float32 clip of the sanitiser decides ℓ's last bit). The single env, the vector env (200
sub-envs stepped together), the JAX env's decoding and the discrete table must reproduce the
executed actions, rewards, observations and info fields exactly (``==`` on float64, no tolerance).
"""

from __future__ import annotations

import csv
import gzip
import json
import os
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.envs.vector import SolarChainVectorEnv

SETTINGS = {"main": False, "no_physics": True}
EPISODES, STEPS = 200, 24
CITIES = ("Beijing", "Shanghai", "Chengdu", "Shenzhen", "Hangzhou")
#: Trace column -> our info key (the trace uses the original's names; ``max_drawdown`` is our ``drawdown``).
INFO_COLUMNS = {
    "absolute_hour": "absolute_hour",
    "episode_start_hour": "episode_start_hour",
    "hour": "hour",
    "reward_ratio": "reward_ratio",
    "liquidity_ratio": "liquidity_ratio",
    "burn_rate": "burn_rate",
    "verified_supply_MWh": "verified_supply_MWh",
    "reported_supply_MWh": "reported_supply_MWh",
    "physics_excess_MWh": "physics_excess_MWh",
    "unsafe_backed_MWh": "unsafe_backed_MWh",
    "artificial_liquidity_MWh": "artificial_liquidity_MWh",
    "physics_violation_rate": "physics_violation_rate",
    "raw_physics_record_rate": "raw_physics_record_rate",
    "demand_MWh": "demand_MWh",
    "matched_energy_MWh": "matched_energy_MWh",
    "unmet_demand_MWh": "unmet_demand_MWh",
    "liquidity": "liquidity",
    "liquidity_depth": "liquidity_depth",
    "token_price": "token_price",
    "max_drawdown": "drawdown",
    "token_drawdown": "token_drawdown",
    "action_jitter": "action_jitter",
    "slippage": "slippage",
}
OBS = [f"obs{i}" for i in range(12)]


@pytest.fixture(scope="module")
def trace_dir(shared_data: Path) -> Path:
    path = shared_data / "original_release_traces"
    if not (path / "env_trace_steps.csv.gz").is_file():
        pytest.skip(f"the original release's env trace is not at {path} (set SOLARCHAIN_SHARED_DATA)")
    return path


@cache
def _read(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """Columns per setting, each a float64 array (every cell parses exactly with ``float``)."""
    with gzip.open(path, "rt", newline="") as handle:
        rows = list(csv.DictReader(handle))
    out: dict[str, dict[str, np.ndarray]] = {}
    for setting in SETTINGS:
        picked = [row for row in rows if row["setting"] == setting]
        out[setting] = {
            key: np.array([float(row[key]) for row in picked])
            for key in picked[0]
            if key not in ("setting", "action_kind")
        }
    return out


@pytest.fixture(scope="module")
def steps(trace_dir: Path) -> dict[str, dict[str, np.ndarray]]:
    return _read(trace_dir / "env_trace_steps.csv.gz")


@pytest.fixture(scope="module")
def resets(trace_dir: Path) -> dict[str, dict[str, np.ndarray]]:
    return _read(trace_dir / "env_trace_resets.csv.gz")


def _actions(trace: dict[str, np.ndarray]) -> np.ndarray:
    return np.stack([trace["a0"], trace["a1"], trace["a2"]], axis=1).astype(np.float32)


def _assert_equal(name: str, got: np.ndarray, expected: np.ndarray, setting: str) -> None:
    got = np.asarray(got, dtype=np.float64)
    bad = np.flatnonzero(got != expected)
    assert bad.size == 0, (
        f"{setting}: {name} differs from the original release at {bad.size} of {expected.size} steps; "
        f"first at global step {bad[0]}: {got[bad[0]]!r} != {expected[bad[0]]!r}"
    )


def test_the_trace_exercises_the_u1_equals_1_clip(steps) -> None:
    actions = _actions(steps["main"])
    at_one = actions[:, 0] == 1.0
    assert int(at_one.sum()) == 479
    # where α + ℓ > 0.98 at u1 = 1, the float32 clip of α (0.64999998, not 0.65) decides ℓ's last bit
    executed_alpha = steps["main"]["reward_ratio"][at_one]
    assert (executed_alpha < 0.65).all()


@pytest.mark.parametrize("setting", list(SETTINGS))
def test_single_env_replays_the_trace_bit_for_bit(published_dir, steps, resets, setting) -> None:
    trace, reset_trace = steps[setting], resets[setting]
    env = SolarChainEnv(data_dir=published_dir, no_physics_penalty=SETTINGS[setting])
    actions = _actions(trace)
    got: dict[str, list[float]] = {key: [] for key in (*INFO_COLUMNS, *OBS, "reward", "truncated")}
    got.update({f"city_reward_{c}": [] for c in CITIES})
    reset_obs, reset_starts = [], []
    for k in range(EPISODES):
        obs, info = env.reset(seed=20260511 + k)
        reset_obs.append(obs)
        reset_starts.append(info["episode_start_hour"])
        for t in range(STEPS):
            obs, reward, terminated, truncated, info = env.step(actions[k * STEPS + t])
            assert not terminated
            got["reward"].append(reward)
            got["truncated"].append(float(truncated))
            for i, value in enumerate(obs.tolist()):
                got[f"obs{i}"].append(value)
            for column, key in INFO_COLUMNS.items():
                got[column].append(info[key])
            for city in CITIES:
                got[f"city_reward_{city}"].append(info["city_rewards"][city])
    reset_obs = np.array(reset_obs, dtype=np.float64)
    for i in range(12):
        _assert_equal(f"reset obs{i}", reset_obs[:, i], reset_trace[f"obs{i}"], setting)
    _assert_equal("episode_start_hour at reset", np.array(reset_starts), reset_trace["episode_start_hour"], setting)
    for key, values in got.items():
        _assert_equal(key, np.array(values), trace[key], setting)


@pytest.mark.parametrize("setting", list(SETTINGS))
def test_vector_env_replays_the_trace_bit_for_bit(published_dir, steps, resets, setting) -> None:
    trace, reset_trace = steps[setting], resets[setting]
    envs = SolarChainVectorEnv(EPISODES, published_dir, no_physics_penalty=SETTINGS[setting])
    actions = _actions(trace).reshape(EPISODES, STEPS, 3)  # sub-env k plays episode k
    obs, _ = envs.reset(seed=20260511)
    for i in range(12):
        _assert_equal(f"reset obs{i}", obs[:, i], reset_trace[f"obs{i}"], setting)
    got: dict[str, np.ndarray] = {}
    for t in range(STEPS):
        obs, reward, _, truncated, info = envs.step(actions[:, t])
        columns = {"reward": reward, "truncated": truncated, **{f"obs{i}": obs[:, i] for i in range(12)}}
        columns.update({column: info[key] for column, key in INFO_COLUMNS.items()})
        cities = list(envs.cities)
        columns.update({f"city_reward_{c}": info["city_rewards"][:, cities.index(c)] for c in CITIES})
        for key, values in columns.items():
            got.setdefault(key, np.empty((EPISODES, STEPS)))[:, t] = values
    for key, values in got.items():
        _assert_equal(f"vector {key}", values.reshape(-1), trace[key], setting)


def test_discrete_table_decodes_the_grid_actions_as_the_original(steps) -> None:
    from solarchain_eval.config import MarketConfig
    from solarchain_eval.market.actions import ActionCodec, DiscreteActions

    trace = steps["main"]
    grid = _actions(trace)[1::2]  # odd global steps: grid points
    index = np.rint(grid * 4).astype(int) @ np.array([25, 5, 1])
    table = DiscreteActions.from_codec(ActionCodec.from_config(MarketConfig()), 5)
    executed = table.decode_batch(index, len(index))
    for row, name in enumerate(("reward_ratio", "liquidity_ratio", "burn_rate")):
        _assert_equal(f"discrete {name}", executed[row], trace[name][1::2], "main")


def _jax_decoded(data_dir: Path, actions: np.ndarray) -> np.ndarray:
    import jax

    from solarchain_eval.envs.jax_env import decode_action
    from solarchain_eval.jax import make_env_params

    decoded = jax.jit(jax.vmap(decode_action, in_axes=(0, None)))(actions, make_env_params(data_dir))
    return np.stack([np.asarray(component) for component in decoded]).astype(np.float64)


def test_jax_decoding_with_x64_equals_the_original_executed_actions(published_dir, trace_dir) -> None:
    """With x64 the JAX env sanitises as the numpy codec does (float32 clip, float64 scale): bit-equal."""
    pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
    env = dict(os.environ, JAX_ENABLE_X64="1", JAX_PLATFORMS="cpu")
    done = subprocess.run(
        [sys.executable, __file__, str(published_dir), str(trace_dir)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == {"x64": True, "differing": [0, 0, 0], "steps": 4800}


def test_jax_decoding_in_float32_is_within_two_ulps_of_the_original(published_dir, steps) -> None:
    """Without x64 the α + ℓ scaling is float32 (two roundings): at most 2 ulps, and exact when unscaled."""
    pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
    trace = steps["main"]
    got = _jax_decoded(published_dir, _actions(trace))
    expected = np.stack([trace["reward_ratio"], trace["liquidity_ratio"], trace["burn_rate"]])
    np.testing.assert_array_max_ulp(got.astype(np.float32), expected.astype(np.float32), maxulp=2)
    unscaled = expected[0] + expected[1] < 0.979
    np.testing.assert_array_equal(got[:, unscaled], expected[:, unscaled])


if __name__ == "__main__":  # the x64 check, in its own process (x64 is a process-wide switch)
    import jax

    trace = _read(Path(sys.argv[2]) / "env_trace_steps.csv.gz")["main"]
    got = _jax_decoded(Path(sys.argv[1]), _actions(trace))
    expected = np.stack([trace["reward_ratio"], trace["liquidity_ratio"], trace["burn_rate"]])
    differing = [int((got[i] != expected[i]).sum()) for i in range(3)]
    print(json.dumps({"x64": bool(jax.config.jax_enable_x64), "differing": differing, "steps": len(expected[0])}))
