"""Output schemas: strict parsing, and the rule planner's two modes (docs/planner_auditor.md#rule-planner)."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from fake_openai import VALID_AUDIT, VALID_PLAN
from solarchain_eval.common.redaction import remove_secret as redact
from solarchain_eval.config import MarketConfig
from solarchain_eval.governance.planner import EpisodeContext, RulePlanner
from solarchain_eval.governance.schemas import AuditorOutput, PlannerOutput, validate_plan
from solarchain_eval.llm.errors import CallSite
from solarchain_eval.market.actions import ActionCodec

CODEC = ActionCodec.from_config(MarketConfig())
SITE = CallSite("planner", "myopic", 1, 0)


def test_nested_extra_fields_and_wrong_types_are_rejected():
    plan = json.loads(json.dumps(VALID_PLAN))
    plan["audit_policy"]["escalate"] = True
    with pytest.raises(ValidationError, match="escalate"):
        PlannerOutput.model_validate_json(json.dumps(plan))
    plan = json.loads(json.dumps(VALID_PLAN))
    plan["audit_policy"]["cooldown_steps"] = 1.5
    with pytest.raises(ValidationError, match="cooldown_steps"):
        PlannerOutput.model_validate_json(json.dumps(plan))
    audit = dict(VALID_AUDIT, final_action=[0.2, 0.6, 0.1])
    with pytest.raises(ValidationError, match="final_action"):
        AuditorOutput.model_validate_json(json.dumps(audit))
    audit = dict(VALID_AUDIT, risk_assessment=dict(VALID_AUDIT["risk_assessment"], physics="catastrophic"))
    with pytest.raises(ValidationError, match="physics"):
        AuditorOutput.model_validate_json(json.dumps(audit))
    # integers are valid numbers
    assert (
        PlannerOutput.model_validate_json(json.dumps(VALID_PLAN).replace("2.0", "2")).audit_policy.slippage_threshold
        == 2.0
    )


def test_a_valid_plan_passes_unchanged():
    plan, events = validate_plan(PlannerOutput.model_validate(VALID_PLAN), CODEC, 24)
    assert events == []
    assert plan.bounds == ((0.05, 0.5), (0.3, 0.9), (0.01, 0.18))
    assert plan.to_log()["audit_policy"] == VALID_PLAN["audit_policy"]


def context(max_violation=0.0, min_gap=0.0, mean_slippage=0.5):
    return EpisodeContext(0, 24, True, max_violation, min_gap, mean_slippage, {})


@pytest.mark.parametrize(
    ("kwargs", "mode"),
    [
        ({}, "rule_balanced"),
        ({"max_violation": 0.01}, "rule_balanced"),  # strict inequalities
        ({"min_gap": -0.10, "mean_slippage": 0.75}, "rule_balanced"),
        ({"max_violation": 0.0101}, "rule_conservative"),
        ({"min_gap": -0.1001}, "rule_conservative"),
        ({"mean_slippage": 0.7501}, "rule_conservative"),
    ],
)
def test_rule_planner_modes(kwargs, mode):
    plan = RulePlanner(CODEC).plan(context(**kwargs), SITE).plan
    assert plan.governance_mode == mode
    if mode == "rule_conservative":
        assert plan.bounds == ((0.05, 0.45), (0.35, 0.95), (0.02, 0.18))
        thresholds = (0.005, -0.05, 0.18, 0.60)
    else:
        assert plan.bounds == ((0.05, 0.65), (0.2, 0.95), (0.0, 0.2))
        thresholds = (0.01, -0.10, 0.25, 0.75)
    assert (plan.violation_threshold, plan.gap_threshold, plan.jitter_threshold, plan.slippage_threshold) == thresholds
    assert (plan.max_audits_per_episode, plan.target_audit_rate, plan.cooldown_steps) == (6, 0.25, 2)


def test_redact_hides_the_key_and_its_long_prefixes():
    key = "sk-abcdefghijklmnop"
    text = f"bad key {key}; did you mean {key[:10]}…?"
    assert key[:8] not in redact(text, key) and "bad key [redacted]" in redact(text, key)
    assert redact("nothing", None) == "nothing"
