"""Property tests: invariants for any action, including NaN and ±inf."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from solarchain_eval.config import MarketConfig
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.market import ActionCodec

F32 = np.float32
CODEC = ActionCodec.from_config(MarketConfig())
# Casting each of α and ℓ to float32 after scaling can round both up: their float64 sum may
# exceed 0.98 by at most one float32 ulp of each (2 × 6e-8); the physics gate caps β anyway.
ALLOCATION_TOLERANCE = 2 * float(np.spacing(F32(1.0)))

any_float32 = st.floats(width=32, allow_nan=True, allow_infinity=True)
actions = arrays(F32, (3,), elements=any_float32)


@given(actions)
@settings(max_examples=400)
def test_decoded_actions_are_always_admissible(action):
    alpha, ell, burn = CODEC.decode(action)
    # Components are clipped to their ranges, then α and ℓ scaled down together when
    # α + ℓ > 0.98: α can fall to 0.05 · 0.98 / (0.05 + 0.95) = 0.049 (the paper's PPO rows).
    assert 0.049 - 1e-7 <= alpha <= 0.65 and 0.2 - 1e-8 <= ell <= 0.95 and 0.0 <= burn <= float(F32(0.2))
    assert alpha + ell <= 0.98 + ALLOCATION_TOLERANCE
    if alpha + ell < 0.98 - ALLOCATION_TOLERANCE:  # not scaled: α is in its own range
        assert alpha >= float(F32(0.05))
    assert all(v == float(F32(v)) for v in (alpha, ell, burn))  # executed actions are float32


@given(arrays(F32, (17, 3), elements=any_float32))
@settings(max_examples=200)
def test_batch_decoding_equals_scalar_decoding(batch):
    decoded = CODEC.decode_batch(batch)
    for i in range(len(batch)):
        assert tuple(decoded[:, i].tolist()) == CODEC.decode(batch[i])


@pytest.fixture(scope="module")
def env(tiny_dataset):
    return SolarChainEnv(tiny_dataset)


@given(seed=st.integers(0, 2**31 - 1), episode=arrays(F32, (24, 3), elements=any_float32))
@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture], deadline=None)
def test_state_invariants_hold_for_any_action_sequence(env, seed, episode):
    env.reset(seed=seed)
    for action in episode:
        _, reward, _, _, info = env.step(action)
        assert np.isfinite(reward)
        assert info["liquidity"] >= 0.0
        assert info["token_price"] >= 0.05
        assert 0.0 <= info["physics_violation_rate"] <= 1.0
        assert info["reward_ratio"] + info["liquidity_ratio"] <= 0.98 + ALLOCATION_TOLERANCE
        assert 0.0 <= info["drawdown"] <= 1.0 and 0.0 <= info["token_drawdown"] < 1.0
        assert info["unmet_demand_MWh"] >= 0.0 and info["matched_energy_MWh"] >= 0.0
