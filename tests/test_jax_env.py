"""The JAX environment equals the numpy environment step for step.

Both are driven with the same start hours, price shocks and actions (random, including NaN and
±inf components); every per-step quantity, the observation and the per-city rewards are compared.
With x64 the agreement is per element to 1e-12 relative (run in a subprocess, since x64 is a
process-wide switch). In float32 the hourly inputs themselves are rounded to float32 (6e-8
relative), so quantities computed by cancellation (1 - L/peak) cannot be per-element accurate;
there the bound is 1e-6 of the quantity's largest magnitude on the trajectory, with unit scale
for the dimensionless fractions (drawdowns, violation rate) and, for the reward, the sum of the
magnitudes of its terms (it is a difference of them). See docs/jax.md.

Run as a script (``python tests/test_jax_env.py DATA_DIR``) it prints the errors as JSON.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
pytest.importorskip("gymnax", reason="the JAX backend is optional: pip install -e '.[jax]'")

#: Fractions in [0, 1] whose natural scale is 1 (see the module docstring).
UNIT_SCALE = {"drawdown", "token_drawdown", "physics_violation_rate", "cost"}
SETTINGS = [("continuous", False), ("continuous", True), ("discrete", False)]


def random_actions(rng: np.random.Generator, mode: str, steps: int, n_actions: int) -> np.ndarray:
    if mode == "discrete":
        return rng.integers(0, n_actions, size=steps)
    actions = rng.uniform(-0.5, 1.5, size=(steps, 3)).astype(np.float32)
    special = rng.random((steps, 3)) < 0.15
    actions[special] = rng.choice(np.array([np.nan, np.inf, -np.inf], dtype=np.float32), size=int(special.sum()))
    return actions


def trajectory_errors(data_dir: Path, mode: str, no_physics: bool, episodes: int = 12, seed: int = 5) -> dict:
    """Largest per-element relative and scaled errors per quantity over ``episodes`` episodes."""
    import jax

    from solarchain_eval.data.table import load_table
    from solarchain_eval.envs.env import SolarChainEnv
    from solarchain_eval.jax import SolarChainJaxEnv, make_env_params
    from solarchain_eval.market.dynamics import RewardWeights

    table = load_table(data_dir)
    np_env = SolarChainEnv(table=table, seed=seed, action_mode=mode, no_physics_penalty=no_physics)
    params = make_env_params(table=table, action_mode=mode, no_physics_penalty=no_physics)
    jax_env = SolarChainJaxEnv(params)

    @jax.jit
    def rollout(state, actions):
        def one(state, action):
            obs, state, reward, done, info = jax_env.step_env(jax.random.key(0), state, action, params)
            return state, (obs, reward, done, info)

        return jax.lax.scan(one, state, actions)[1]

    w = RewardWeights.from_config(np_env.config)
    rng = np.random.default_rng(seed)
    reward_terms = []
    numpy_rows: dict[str, list] = {}
    jax_rows: dict[str, list] = {}
    for _ in range(episodes):
        obs, _ = np_env.reset()
        jax_obs, state = jax_env.reset_to(np_env.episode_start_hour, np.array(np_env._noise), params)
        numpy_rows.setdefault("observation", []).append(obs)
        jax_rows.setdefault("observation", []).append(np.asarray(jax_obs))
        actions = random_actions(rng, mode, np_env.episode_steps, np_env.action_space.n if mode == "discrete" else 0)
        j_obs, j_reward, j_done, j_info = jax.device_get(rollout(state, actions))
        for k, action in enumerate(actions):
            obs, reward, _, truncated, info = np_env.step(action)
            assert bool(j_done[k]) == truncated
            values = {key: info[key] for key in info if key != "city_rewards"}
            values["city_rewards"] = list(info["city_rewards"].values())
            values["observation"] = obs
            values["reward_returned"] = reward
            reward_terms.append(
                info["matched_energy_MWh"]
                + w.drawdown * info["drawdown"]
                + w.jitter * info["action_jitter"]
                + w.unmet * info["unmet_demand_MWh"]
                + w.fairness * info["fairness_variance"]
                + w.physics * info["cost"]
            )
            jax_values = {key: j_info[key][k] for key in values if key in j_info}
            jax_values["observation"], jax_values["reward_returned"] = j_obs[k], j_reward[k]
            for key, value in values.items():
                numpy_rows.setdefault(key, []).append(np.asarray(value, dtype=np.float64))
                jax_rows.setdefault(key, []).append(np.asarray(jax_values[key], dtype=np.float64))
    errors = {}
    for key, rows in numpy_rows.items():
        a, b = np.array(rows), np.array(jax_rows[key])
        assert np.isfinite(a).all() and np.isfinite(b).all(), key
        diff = np.abs(a - b)
        elementwise = float(np.max(diff / np.maximum(np.abs(a), 1e-300), initial=0.0, where=diff > 0))
        floor = 1.0 if key in UNIT_SCALE else (max(reward_terms) if key.startswith("reward") else 0.0)
        scale = max(float(np.abs(a).max()), floor, 1e-300)
        errors[key] = {"elementwise": elementwise, "scaled": float(diff.max() / scale)}
    return errors


@pytest.mark.parametrize(("mode", "no_physics"), SETTINGS)
def test_float32_matches_numpy_env(tiny_dataset: Path, mode: str, no_physics: bool) -> None:
    errors = trajectory_errors(tiny_dataset, mode, no_physics)
    assert len(errors) >= 28  # every STEP_INFO_KEYS entry, step, obs, rewards, city rewards
    worst = {key: e["scaled"] for key, e in errors.items() if e["scaled"] > 1e-6}
    assert not worst, worst


def test_float32_matches_numpy_env_on_paper_data(published_dir: Path) -> None:
    errors = trajectory_errors(published_dir, "continuous", False, episodes=20)
    worst = {key: e["scaled"] for key, e in errors.items() if e["scaled"] > 1e-6}
    assert not worst, worst


def test_x64_matches_numpy_env_per_element(tiny_dataset: Path) -> None:
    env = dict(os.environ, JAX_ENABLE_X64="1", JAX_PLATFORMS="cpu")
    done = subprocess.run(
        [sys.executable, __file__, str(tiny_dataset)], env=env, capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads(done.stdout.strip().splitlines()[-1])
    assert results["x64"] is True
    for setting, errors in results["settings"].items():
        worst = {key: e["elementwise"] for key, e in errors.items() if e["elementwise"] > 1e-12}
        assert not worst, (setting, worst)


def test_reset_draws_admissible_starts_and_scaled_noise(tiny_dataset: Path) -> None:
    import jax

    from solarchain_eval.jax import SolarChainJaxEnv, make_env_params

    params = make_env_params(tiny_dataset)
    env = SolarChainJaxEnv(params)
    keys = jax.random.split(jax.random.key(1), 512)
    obs, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    starts = np.asarray(state.start)
    assert set(starts.tolist()) == {0, 24, 48, 72}  # 4 days: every midnight with a full day after it
    assert obs.shape == (512, 12) and obs.dtype == np.float32
    assert abs(float(np.std(np.asarray(state.noise))) - 0.004) < 0.0003


if __name__ == "__main__":
    import jax

    print(
        json.dumps(
            {
                "x64": bool(jax.config.jax_enable_x64),
                "settings": {f"{m}-{p}": trajectory_errors(Path(sys.argv[1]), m, p) for m, p in SETTINGS},
            }
        )
    )
