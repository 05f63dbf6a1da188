"""Scheduler properties (hypothesis) and the budget, bounds and trigger helpers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from solarchain_eval.config import MarketConfig
from solarchain_eval.governance.scheduler import (
    SKIP_BUDGET,
    SKIP_COOLDOWN,
    AuditScheduler,
    audit_budget,
    bound_action,
    hard_reasons,
    kappa,
    soft_trigger,
)
from solarchain_eval.governance.schemas import Plan
from solarchain_eval.market.actions import ActionCodec

CODEC = ActionCodec.from_config(MarketConfig())

triggers = st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=48)


@settings(max_examples=400, deadline=None)
@given(triggers, st.integers(1, 24), st.integers(0, 24))
def test_hard_trigger_never_skipped_and_soft_audits_respect_budget_and_cooldown(flags, budget, cooldown):
    scheduler = AuditScheduler(budget, cooldown)
    used, last_audit = 0, None
    soft_only_audits = 0
    for step, (hard, soft) in enumerate(flags):
        decision = scheduler.step(step, hard, soft)
        if hard:
            assert decision.audited and decision.skip_reason is None
        if not (hard or soft):
            assert not decision.audited and decision.skip_reason is None
        if decision.audited and not hard:
            soft_only_audits += 1
            assert used < budget  # budget checked against every audit so far, hard ones included
            if cooldown > 0 and last_audit is not None:
                assert step - last_audit > cooldown
        if not decision.audited and soft and not hard:
            expected = SKIP_BUDGET if used >= budget else SKIP_COOLDOWN
            assert decision.skip_reason == expected
            if expected == SKIP_COOLDOWN:
                assert cooldown > 0 and last_audit is not None and step - last_audit <= cooldown
        if decision.audited:
            used += 1
            last_audit = step
        assert decision.audits_used == used == scheduler.audits_used
    assert soft_only_audits <= budget


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 24), st.integers(0, 24), st.integers(1, 24))
def test_soft_only_sequence_audits_exactly_every_cooldown_until_budget(budget, cooldown, length):
    scheduler = AuditScheduler(budget, cooldown)
    audited = [step for step in range(length) if scheduler.step(step, False, True).audited]
    expected = list(range(0, length, cooldown + 1))[:budget]
    assert audited == expected


def test_hard_audits_count_against_the_budget():
    scheduler = AuditScheduler(budget=2, cooldown_steps=0)
    assert scheduler.step(0, True, False).audited
    assert scheduler.step(1, True, False).audited
    assert scheduler.step(2, True, False).audited  # hard: past the budget
    decision = scheduler.step(3, False, True)
    assert not decision.audited and decision.skip_reason == SKIP_BUDGET and decision.audits_used == 3


def test_cooldown_counts_from_hard_audits_too():
    scheduler = AuditScheduler(budget=10, cooldown_steps=2)
    assert scheduler.step(5, True, False).audited
    assert scheduler.step(7, False, True).skip_reason == SKIP_COOLDOWN
    assert scheduler.step(8, False, True).audited


@pytest.mark.parametrize(
    ("max_audits", "rate", "expected"),
    [
        (6, 0.25, 6),
        (6, 0.1, 2),  # round(2.4) = 2
        (6, 0.0, 1),  # at least one
        (30, 1.0, 24),  # clipped to the episode
        (4, 0.5, 4),
        (24, 0.0625, 2),  # 1.5 -> 2 (half to even)
        (24, 0.1041666666666666, 2),  # 2.4999... -> 2
        (24, 0.1875, 4),  # 4.5 -> 4 (half to even, unlike Python 2's round-half-up)
    ],
)
def test_audit_budget(max_audits, rate, expected):
    assert audit_budget(max_audits, rate, 24) == expected


def _plan(**overrides) -> Plan:
    values = dict(
        governance_mode="t",
        bounds=((0.05, 0.45), (0.35, 0.95), (0.02, 0.18)),
        violation_threshold=0.1,
        gap_threshold=-0.05,
        jitter_threshold=0.18,
        slippage_threshold=0.6,
        max_audits_per_episode=6,
        target_audit_rate=0.25,
        cooldown_steps=2,
        rationale="",
    )
    values.update(overrides)
    return Plan(**values)


def test_bound_action_clips_in_float32_then_scales_to_the_allocation_cap():
    plan = _plan()
    bounded = bound_action((0.6, 0.9, 0.0), plan, CODEC)
    # α clipped to float32(0.45); then α + ℓ = 1.35 > 0.98: both scaled, float64 work, float32 out.
    alpha, ell = float(np.float32(0.45)), float(np.float32(0.9))
    scale = 0.98 / (alpha + ell)
    assert bounded == (float(np.float32(alpha * scale)), float(np.float32(ell * scale)), float(np.float32(0.02)))


def test_kappa_is_the_float32_l1_norm():
    f32 = np.float32
    a = tuple(float(f32(v)) for v in (0.3, 0.5, 0.1))
    b = tuple(float(f32(v)) for v in (0.25, 0.75, 0.02))
    expected = (abs(f32(a[0]) - f32(b[0])) + abs(f32(a[1]) - f32(b[1]))) + abs(f32(a[2]) - f32(b[2]))
    assert kappa(a, b) == float(expected)
    # The float64 sum of the same differences is a different number here.
    assert kappa(a, b) != abs(a[0] - b[0]) + abs(a[1] - b[1]) + abs(a[2] - b[2])


def test_soft_trigger_compares_at_float32_precision():
    k = float(np.float32(0.14))  # 0.14000000059604645 > 0.14 in float64
    assert not soft_trigger(k, _plan(jitter_threshold=0.14))
    assert soft_trigger(float(np.nextafter(np.float32(0.14), np.float32(1))), _plan(jitter_threshold=0.14))


def test_hard_reasons_compare_at_float32_precision():
    plan = _plan(violation_threshold=0.1, gap_threshold=-0.1, slippage_threshold=0.75)
    nu = float(np.float32(5 / 50))  # 0.10000000149…: equal to the threshold in float32
    assert hard_reasons(nu, 0.0, 0.0, plan) == []
    assert hard_reasons(float(np.float32(6 / 50)), float(np.float32(-0.2)), 0.8, plan) == [
        "violation",
        "gap",
        "slippage",
    ]
    assert hard_reasons(0.0, float(np.float32(-0.1)), float(np.float32(0.75)), plan) == []
