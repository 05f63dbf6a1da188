"""The threshold tie between the scheduler's float32 triggers and the rule auditor's float64 risks.

An LLM plan (served by the local test server) sets the violation threshold τν = 0.14. On the
published data ν = 7/50 is read from the float32 observation as float32(0.14) =
0.14000000059604645: equal to the threshold at float32 precision, so no hard trigger fires; the
soft trigger (τκ = 0) still calls the rule auditor, which re-tests ν > τν in float64 and applies
the physics revision as well as the jitter smoothing (the Planner/Auditor page in docs/).
"""

from __future__ import annotations

import numpy as np
from pydantic import SecretStr

from fake_openai import VALID_PLAN, FakeOpenAI, Seen, ok
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.governance import AgenticOptions, Governance
from solarchain_eval.governance.factory import LLMOptions
from solarchain_eval.llm.client import LLMSettings
from solarchain_eval.market.baselines import make_baseline

F32 = np.float32
TIE_PLAN = {
    **VALID_PLAN,
    "governance_mode": "llm_tie_test",
    "action_bounds": {
        "reward_ratio": {"low": 0.05, "high": 0.65},
        "liquidity_ratio": {"low": 0.2, "high": 0.95},
        "burn_rate": {"low": 0.0, "high": 0.2},
    },
    "audit_policy": {
        "violation_threshold": 0.14,
        "gap_threshold": -1.0,  # gap >= -1 always: never a liquidity trigger
        "jitter_threshold": 0.0,  # every change of action is a soft trigger
        "slippage_threshold": 10.0,
        "max_audits_per_episode": 24,
        "target_audit_rate": 1.0,
        "cooldown_steps": 0,
    },
}


def plan_only(seen: Seen):
    return ok(seen.path, TIE_PLAN)


def expected_revision(bounded, previous) -> list[float]:
    """Physics revision then jitter smoothing, float32 arithmetic, float64 sanitising."""
    a = np.array(bounded, dtype=F32)
    a[0] *= F32(0.85)
    a[1] *= F32(0.90)
    a[2] = max(a[2], F32(0.12))
    a = F32(0.6) * np.array(previous, dtype=F32) + F32(0.4) * a
    x = np.clip(a.astype(np.float64), [0.05, 0.20, 0.0], [0.65, 0.95, 0.20])
    if x[0] + x[1] > 0.98:
        x[:2] *= 0.98 / (x[0] + x[1])
    return x.astype(F32).tolist()


def test_soft_audit_on_a_violation_tie_applies_the_physics_revision(published_dir):
    config = BenchmarkConfig()
    env = SolarChainEnv(config=config, table=load_table(published_dir))
    with FakeOpenAI(responder=plan_only) as server:
        settings = LLMSettings(api="chat", model="fake-model", base_url=server.base_url, api_key=SecretStr("sk-test"))
        options = AgenticOptions(planner="llm", auditor="rule", llm=LLMOptions(settings))
        with Governance(options, config.market) as governance:
            results = list(
                run_policy(
                    env, governance.wrap(make_baseline("random")), setting="llm", run_seeds=[20260511], episodes=8
                )
            )
    rows = [row for result in results for row in result.extras["agentic_log"]]
    assert {row["plan"]["governance_mode"] for row in rows} == {"llm_tie_test"}
    ties = [row for row in rows if row["raw_violation_rate"] == float(F32(0.14))]
    assert ties, "no step with ν = float32(0.14) in these episodes"
    for row in ties:
        assert row["raw_violation_rate"] > 0.14  # the float64 comparison holds ...
        assert not row["hard_trigger"] and row["hard_reasons"] == []  # ... the float32 one does not
        assert row["soft_trigger"] and row["audited"] and row["decision"] == "revise"
        previous = (
            rows[rows.index(row) - 1]["executed_action"] if row["step"] > 0 else [F32(0.25), F32(0.75), F32(0.02)]
        )
        assert row["final_action"] == expected_revision(row["bounded_action"], previous)
        assert "physics" in row["reason"] and "jitter" in row["reason"]
        # Physics revision lifts the burn rate to at least 0.6 b_prev + 0.4 · 0.12.
        assert row["final_action"][2] >= float(F32(0.6) * F32(previous[2]) + F32(0.048)) - 1e-7
