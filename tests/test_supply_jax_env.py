"""The supply-chain JAX twin equals the numpy single env over whole episodes.

Both run from the same start days and price shocks; the numpy env is driven by a baseline policy
(static, random, myopic, base-stock; random indices in discrete mode, random actions with NaN and
±inf components as a fifth policy) and the JAX env replays its executed actions in a jitted
``lax.scan``. Observations, rewards and every step field are compared, with and without the
feasibility penalty. The standard is the solar twin's (tests/test_jax_env.py): with x64 every
element agrees to 1e-12 relative (run in a subprocess, x64 being a process-wide switch; XLA may
fuse a multiply and an add into one rounding, so bit equality is not promised); in float32 the
inputs are themselves rounded to 6e-8 relative, so the bound is 1e-6 of the quantity's largest
magnitude on the trajectory (unit scale for the dimensionless fractions; for a difference of two
quantities, the larger operand's: the sum of the magnitudes of its terms for the reward, filled
units for the unsafe units = filled - delivered, and so on). The regions' fill rates are held to
1e-5: a warehouse drawn empty keeps in float32 a residue of about 1e-7 of its stock, which the rate
divides by that day's (smaller) regional demand.

Run as a script (``python tests/test_supply_jax_env.py DATA_DIR``) it prints the errors as JSON.
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

from supply_fixtures import supply_dir, supply_table  # noqa: E402, F401

#: Fractions whose natural scale is 1 (see the module docstring).
UNIT_SCALE = {"violation_rate", "price_drawdown", "cost", "capacity_check_rate", "region_fill_rates"}
#: Differences and the quantity whose magnitude is their scale (the larger operand).
OPERAND_SCALE = {
    "unsafe_units": "filled_units",
    "unmet_units": "effective_demand_units",
    "backlog_units": "effective_demand_units",
    "phantom_stock_units": "reported_stock_units",
    "phantom_fill_volume_units": "reported_stock_units",
}
#: Ratios of one region's quantities (see the module docstring).
RATIOS = {"region_fill_rates"}
POLICIES = ("static", "random", "myopic", "base-stock", "wild")
#: (policy, action mode, no_physics_penalty)
SETTINGS = [(p, "continuous", off) for p in POLICIES for off in (False, True)] + [
    ("random-index", "discrete", False),
    ("random-index", "discrete", True),
]


def _actor(policy: str, mode: str, n_actions: int, seed: int):
    from solarchain_eval.supply.baselines import make_supply_baseline

    rng = np.random.default_rng(seed)
    if policy == "random-index":
        return lambda obs: rng.integers(0, n_actions)
    if policy == "wild":  # out of range, NaN and ±inf components: sanitised alike

        def wild(obs):
            action = rng.uniform(-0.5, 1.5, 3).astype(np.float32)
            special = rng.random(3) < 0.15
            action[special] = rng.choice(np.array([np.nan, np.inf, -np.inf], np.float32), int(special.sum()))
            return action

        return wild
    agent = make_supply_baseline(policy)
    agent.begin_run(seed)
    return agent.act


def trajectory_errors(data_dir: Path, policy: str, mode: str, no_penalty: bool, episodes: int = 6, seed: int = 3):
    """Largest per-element relative and scaled errors per quantity over ``episodes`` episodes."""
    import jax

    from solarchain_eval.supply.env import STEP_FIELDS, SupplyChainEnv
    from solarchain_eval.supply.jax_env import make_supply_jax_env
    from solarchain_eval.supply.table import load_supply_table

    table = load_supply_table(data_dir)
    np_env = SupplyChainEnv(table=table, seed=seed, action_mode=mode, no_physics_penalty=no_penalty)
    jax_env = make_supply_jax_env(None, table, action_mode=mode, no_physics_penalty=no_penalty)
    params = jax_env.default_params
    act = _actor(policy, mode, params.grid.shape[0], seed)
    w = np_env.inputs.weights

    @jax.jit
    def rollout(state, actions):
        def one(state, action):
            obs, state, reward, done, info = jax_env.step_env(jax.random.key(0), state, action, params)
            return state, (obs, reward, done, info)

        state, outputs = jax.lax.scan(one, state, actions)
        return state, outputs

    numpy_rows: dict[str, list] = {}
    jax_rows: dict[str, list] = {}
    reward_terms = []

    def add(key, a, b):
        numpy_rows.setdefault(key, []).append(np.asarray(a, dtype=np.float64))
        jax_rows.setdefault(key, []).append(np.asarray(b, dtype=np.float64))

    for _ in range(episodes):
        obs, info = np_env.reset()
        jax_obs, state = jax_env.reset_to(info["episode_start_day"], np.array(np_env._noise), params)
        add("observation", obs, jax_obs)
        actions, steps = [], []
        while True:
            action = act(obs)
            obs, reward, _, truncated, info = np_env.step(action)
            actions.append(action)
            steps.append((obs, reward, truncated, info))
            if truncated:
                break
        state, (j_obs, j_reward, j_done, j_info) = jax.device_get(rollout(state, np.array(actions)))
        for k, (obs_k, reward, truncated, info) in enumerate(steps):
            assert bool(j_done[k]) == truncated
            add("observation", obs_k, j_obs[k])
            add("reward_returned", reward, j_reward[k])
            add("region_fill_rates", list(info["region_fill_rates"].values()), j_info["region_fill_rates"][k])
            for key in (*STEP_FIELDS, "step"):
                add(key, info[key], j_info[key][k])
            reward_terms.append(
                info["filled_units"] / np_env.inputs.params.scale_units
                + w.drawdown * info["price_drawdown"]
                + w.jitter * info["action_jitter"]
                + w.unmet * info["unmet_units"] / np_env.inputs.params.scale_units
                + w.fairness * info["fairness_variance"]
                + w.feasibility * info["cost"]
            )
        totals = np.asarray(list(np_env.region_totals.values()))
        add("region_totals", totals, np.stack([state.region_filled, state.region_effective], axis=-1))
    errors = {}
    for key, rows in numpy_rows.items():
        a, b = np.array(rows), np.array(jax_rows[key])
        assert np.isfinite(a).all() and np.isfinite(b).all(), key
        diff = np.abs(a - b)
        elementwise = float(np.max(diff / np.maximum(np.abs(a), 1e-300), initial=0.0, where=diff > 0))
        floor = 1.0 if key in UNIT_SCALE else (max(reward_terms) if key.startswith("reward") else 0.0)
        if key in OPERAND_SCALE:
            floor = float(np.abs(np.array(numpy_rows[OPERAND_SCALE[key]])).max())
        scale = max(float(np.abs(a).max()), floor, 1e-300)
        errors[key] = {"elementwise": elementwise, "scaled": float(diff.max() / scale), "bit_equal": not diff.any()}
    return errors


@pytest.mark.parametrize(("policy", "mode", "no_penalty"), SETTINGS)
def test_float32_twin_matches_the_numpy_env(supply_dir, policy, mode, no_penalty):  # noqa: F811
    from solarchain_eval.supply.env import STEP_FIELDS

    errors = trajectory_errors(supply_dir, policy, mode, no_penalty)
    assert len(errors) == len(STEP_FIELDS) + 5  # + step, obs, returned reward, fill rates, region totals
    worst = {key: e["scaled"] for key, e in errors.items() if e["scaled"] > (1e-5 if key in RATIOS else 1e-6)}
    assert not worst, worst
    # Integers and the executed levers (float32 on both sides) agree exactly.
    exact = ("day", "episode_start_day", "step", "supplier_incentive", "release_ratio", "demand_damping")
    assert all(errors[key]["bit_equal"] for key in exact), {key: errors[key] for key in exact}


def test_x64_twin_matches_the_numpy_env_per_element(supply_dir):  # noqa: F811
    env = dict(os.environ, JAX_ENABLE_X64="1", JAX_PLATFORMS="cpu")
    done = subprocess.run(
        [sys.executable, __file__, str(supply_dir)], env=env, capture_output=True, text=True, timeout=600, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads(done.stdout.strip().splitlines()[-1])
    assert results["x64"] is True
    assert len(results["settings"]) == len(SETTINGS)
    for setting, errors in results["settings"].items():
        worst = {key: e["elementwise"] for key, e in errors.items() if e["elementwise"] > 1e-12}
        assert not worst, (setting, worst)


if __name__ == "__main__":
    import jax

    print(
        json.dumps(
            {
                "x64": bool(jax.config.jax_enable_x64),
                "settings": {
                    f"{p}-{m}-{off}": trajectory_errors(Path(sys.argv[1]), p, m, off) for p, m, off in SETTINGS
                },
            }
        )
    )


def test_the_task_builds_the_twin_which_resets_and_autoresets_under_jit_and_vmap(supply_table):  # noqa: F811
    import jax

    from solarchain_eval.config import BenchmarkConfig
    from solarchain_eval.supply.env import SupplyInputs
    from solarchain_eval.supply.jax_env import SupplyChainJaxEnv
    from solarchain_eval.supply.task import SUPPLY_TASK

    config = BenchmarkConfig().with_updates(episode_steps=5)
    env = SUPPLY_TASK.make_jax_env(config, supply_table)
    assert isinstance(env, SupplyChainJaxEnv)
    params = env.default_params
    steps = params.episode_steps
    assert steps == 5
    n = 256
    obs, state = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(jax.random.split(jax.random.key(1), n), params)
    assert obs.shape == (n, 15) and obs.dtype == np.float32
    admissible = SupplyInputs(supply_table, config).starts.tolist()
    assert set(np.asarray(state.start).tolist()) == set(admissible)  # every admissible Monday is drawn
    assert abs(float(np.std(np.asarray(state.noise))) - 0.004) < 0.0004
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    actions = np.full((n, 3), 0.5, np.float32)
    for k in range(steps):
        keys = jax.random.split(jax.random.key(10 + k), n)
        obs, state, reward, done, info = step(keys, state, actions, params)
        assert bool(np.all(np.asarray(done))) == (k == steps - 1)
    # gymnax's step started every env's next episode; the last day's observation is kept in info.
    assert not np.asarray(state.time).any() and not np.array_equal(np.asarray(info["terminal_obs"]), np.asarray(obs))
    assert np.asarray(info["region_fill_rates"]).shape == (n, 5)


def test_the_generic_jax_factory_builds_the_twin_in_either_action_mode(supply_table):  # noqa: F811
    """``tasks.base.make_jax_env`` (what the JAX trainer and the benches call) passes the action mode on."""
    from solarchain_eval.config import BenchmarkConfig
    from solarchain_eval.tasks import get_task
    from solarchain_eval.tasks.base import make_jax_env

    task = get_task("supply-chain")
    discrete = make_jax_env(task, BenchmarkConfig(), supply_table, action_mode="discrete")
    assert discrete.action_space(discrete.default_params).n == 125
    continuous = make_jax_env(task, BenchmarkConfig(), supply_table, action_mode="continuous")
    assert continuous.action_space(continuous.default_params).shape == (3,)
