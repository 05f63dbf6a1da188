"""Bootstrapping at the time limit in the JAX backend, as SB3 does (docs/jax.md).

Every SolarChain episode is cut after its 24th hour. SB3 bootstraps there: PPO adds
γ·V(terminal obs) to the last reward, and SAC's and DQN's replay buffers
(``handle_timeout_termination``) store the true last observation as the next one with done
False. The rollouts and transitions the aligned rejax algorithms collect are checked here
against the environment stepped independently (``step_env`` from the same states with the
same actions), and rejax's own algorithms, which end the return at the 24th hour, are shown
to fail the same checks.
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
pytest.importorskip("rejax", reason="the JAX backend is optional: pip install -e '.[jax]'")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from solarchain_eval.config import BenchmarkConfig  # noqa: E402
from solarchain_eval.envs.jax_env import SolarChainJaxEnv, make_env_params  # noqa: E402
from solarchain_eval.training.jax_algorithm import make_algo, rejax_config  # noqa: E402

HOURS = 24


def _algorithm(algo: str, tiny_dataset, aligned: bool, timesteps: int = 2048):
    """The backend's algorithm (``aligned``) or rejax's own with the same settings."""
    import rejax

    config = BenchmarkConfig()
    params = make_env_params(tiny_dataset, action_mode="discrete" if algo == "dqn" else "continuous")
    if aligned:
        return make_algo(algo, SolarChainJaxEnv(params), config, timesteps), params
    settings = rejax_config(algo, config, timesteps)
    return rejax.get_algo(algo).create(env=SolarChainJaxEnv(params), env_params=params, **settings), params


def _one(tree, i: int):
    return jax.tree.map(lambda x: x[i], tree)


def _env_episode(params, state, actions):
    """``step_env`` over one episode from ``state``: (observation after each step, rewards)."""
    env = SolarChainJaxEnv(params)
    observations, rewards = [], []
    for action in actions:
        obs, state, reward, done, info = env.step_env(jax.random.key(0), state, action, params)
        observations.append(np.asarray(obs))
        rewards.append(float(reward))
    assert bool(done) and bool(info["truncated"])
    return np.array(observations), np.array(rewards), state


def _check_ppo_rollout(instance, params) -> None:
    """The stored reward at the 24th step is env reward + γ·V(terminal obs); the others are the env's."""
    instance = instance.replace(num_steps=2 * HOURS, num_minibatches=1)
    ts = instance.init_state(jax.random.key(5))
    _, rollout = jax.jit(instance.collect_trajectories)(ts)
    space = SolarChainJaxEnv(params).action_space(params)
    actions = np.clip(np.asarray(rollout.action[:HOURS, 0]), space.low, space.high)
    observations, env_rewards, _ = _env_episode(params, _one(ts.env_state, 0), actions)
    np.testing.assert_allclose(np.asarray(rollout.obs[1:HOURS, 0]), observations[:-1], rtol=1e-6)
    assert np.asarray(rollout.done[:, 0]).nonzero()[0].tolist() == [HOURS - 1, 2 * HOURS - 1]
    terminal_obs, reset_obs = observations[-1], np.asarray(rollout.obs[HOURS, 0])
    value = partial(instance.critic.apply, ts.critic_ts.params)
    terminal_value = float(value(jnp.asarray(terminal_obs)[None])[0])
    # The test must tell γ·V(terminal) from V(terminal), from γ·V(reset obs) and from nothing.
    assert abs(terminal_value) > 1e-2 and abs(terminal_value - float(value(reset_obs[None])[0])) > 1e-2
    stored = np.asarray(rollout.reward[:, 0])
    np.testing.assert_allclose(stored[: HOURS - 1], env_rewards[:-1], rtol=1e-6)
    expected = env_rewards[-1] + instance.gamma * terminal_value
    np.testing.assert_allclose(stored[HOURS - 1], expected, rtol=1e-6, atol=1e-6)


def _check_buffer_transitions(algo: str, instance, params) -> None:
    """At the 24th step the buffer's next obs is the env's pre-reset obs and done is False;
    the next action is chosen from the new episode's first observation."""
    ts = instance.init_state(jax.random.key(6))
    collect = instance.collect_transitions
    if algo == "dqn":
        collect = partial(collect, epsilon=1.0, uniform=False)
    collect = jax.jit(collect)
    start_state, batches = ts.env_state, []
    for _ in range(HOURS):
        ts, batch = collect(ts)
        batches.append(batch)
    env = SolarChainJaxEnv(params)
    for i in range(instance.num_envs):
        actions = [np.asarray(b.action[i]) for b in batches]
        observations, env_rewards, _ = _env_episode(params, _one(start_state, i), actions)
        # rtol: the jitted vmapped step and this eager one may round an ulp apart (XLA fusions)
        np.testing.assert_allclose(np.array([np.asarray(b.next_obs[i]) for b in batches]), observations, rtol=1e-6)
        np.testing.assert_allclose([float(b.reward[i]) for b in batches], env_rewards, rtol=1e-6)
        assert not any(bool(b.done[i]) for b in batches)
        # After the auto-reset: the new episode's first observation, not the terminal one.
        new_episode = _one(ts.env_state, i)
        assert int(new_episode.time) == 0
        reset_obs, _ = env.reset_to(new_episode.start, new_episode.noise, params)
        np.testing.assert_allclose(np.asarray(ts.last_obs[i]), np.asarray(reset_obs), rtol=1e-6)
        assert np.max(np.abs(np.asarray(reset_obs) - observations[-1])) > 0.1


def test_ppo_adds_the_discounted_value_of_the_terminal_observation(tiny_dataset):
    _check_ppo_rollout(*_algorithm("ppo", tiny_dataset, aligned=True))


@pytest.mark.parametrize("algo", ["sac", "dqn"])
def test_replay_buffer_stores_the_terminal_observation_not_done(algo, tiny_dataset):
    _check_buffer_transitions(algo, *_algorithm(algo, tiny_dataset, aligned=True, timesteps=1000))


@pytest.mark.parametrize("algo", ["ppo", "sac", "dqn"])
def test_rejax_without_the_alignment_fails_these_checks(algo, tiny_dataset):
    """rejax's own algorithms end the return at the 24th hour: the checks above must catch that."""
    instance, params = _algorithm(algo, tiny_dataset, aligned=False, timesteps=2048 if algo == "ppo" else 1000)
    with pytest.raises(AssertionError, match="Not equal to tolerance"):  # the reward or the next obs
        if algo == "ppo":
            _check_ppo_rollout(instance, params)
        else:
            _check_buffer_transitions(algo, instance, params)


def test_terminal_observation_and_truncation_in_info(tiny_dataset):
    """gymnax's step returns the reset observation after the 24th hour; info keeps the last one."""
    params = make_env_params(tiny_dataset)
    env = SolarChainJaxEnv(params)
    obs, state = env.reset(jax.random.key(1), params)
    step = jax.jit(env.step)
    for hour in range(HOURS):
        previous = state
        obs, state, _, done, info = step(jax.random.key(hour), state, jnp.full(3, 0.5), params)
        assert bool(done) == bool(info["truncated"]) == (hour == HOURS - 1)
        own, _, _, _, _ = env.step_env(jax.random.key(0), previous, jnp.full(3, 0.5), params)
        np.testing.assert_array_equal(np.asarray(info["terminal_obs"]), np.asarray(own))
        if hour < HOURS - 1:
            np.testing.assert_array_equal(np.asarray(obs), np.asarray(own))
    assert int(state.time) == 0 and not np.array_equal(np.asarray(obs), np.asarray(info["terminal_obs"]))
