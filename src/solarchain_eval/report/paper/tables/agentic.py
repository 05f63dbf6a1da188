"""Planner/Auditor tables: operation rates, trigger diagnostics and the case-study audit trace."""

from __future__ import annotations

import pandas as pd

from ....evaluation.records import ACTIONS_FILE, AGENTIC_LOG_FILE
from ....evaluation.settings import SETTING_AGENTIC, SETTING_AGENTIC_NO_PHYSICS
from ...loading import ReportData
from ...naming import AGENTIC_REWARD_LABELS, governance_layer, paper_order, policy_label, setting_label
from ...options import ReportOptions
from ...table_model import Column, ReportTable, Skipped, basis_sentence, cell, fixed, integer, text
from ..casestudy import select_case
from .common import agentic_rollouts, means, pooled_revision_rate, size_fields, sizes_of

AGENTIC_SETTINGS = (SETTING_AGENTIC, SETTING_AGENTIC_NO_PHYSICS)
TRIGGER_COLUMNS = (
    ("physics_trigger_rate", "Physics Trig."),
    ("gap_trigger_rate", "Gap Trig."),
    ("slippage_trigger_rate", "Slippage Trig."),
    ("soft_trigger_rate", "Jitter Trig."),  # the soft trigger is the jitter condition κ > τκ
    ("plan_violation_threshold", "Viol. Thr."),
    ("plan_gap_threshold", "Gap Thr."),
    ("plan_jitter_threshold", "Jitter Thr."),
    ("plan_slippage_threshold", "Slip Thr."),
)
NO_AGENTIC = "the run has no agentic setting (llm / llm_no_physics): evaluate with the Planner/Auditor layer"


def _agentic_groups(data: ReportData, key: str, title: str):
    """(setting, policy, rows) of every agentic group, or a Skipped."""
    frame, missing = agentic_rollouts(data, AGENTIC_SETTINGS)
    if frame.empty:
        return Skipped(key, title, NO_AGENTIC)
    if missing:
        return Skipped(key, title, f"metrics of the agentic settings lack column(s) {', '.join(missing)}")
    groups = []
    for setting in AGENTIC_SETTINGS:
        in_setting = frame[frame["setting"] == setting]
        for policy in paper_order(in_setting["policy"]):
            groups.append((setting, policy, in_setting[in_setting["policy"] == policy]))
    return groups


def _step_count(data: ReportData, setting: str, policy: str, episodes: int) -> tuple[int, str]:
    """Governance steps of a group: log rows, else action rows, else none."""
    for name, frame in ((AGENTIC_LOG_FILE, data.logs), (ACTIONS_FILE, data.actions)):
        if not frame.empty:
            rows = int(((frame["setting"] == setting) & (frame["policy"] == policy)).sum())
            if rows:
                return rows, name
    return 0, "none"


def llm_operations(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Appendix: audit, revision and modification rates, mean action delta, not-triggered rate."""
    layer = governance_layer(data.metrics, data.metadata)
    title = f"Detailed governance operation rates ({layer})"
    groups = _agentic_groups(data, "llm_operations", title)
    if isinstance(groups, Skipped):
        return groups
    rows, sources = [], set()
    for setting, policy, group in groups:
        steps, source = _step_count(data, setting, policy, len(group))
        sources.add(source)
        rows.append(
            {
                "setting": AGENTIC_REWARD_LABELS[setting],
                "policy": policy_label(policy),
                **size_fields(group),
                "steps": steps,
                "audit_rate": float(group["audit_rate"].mean()),
                "revision_given_audit": pooled_revision_rate(group),
                **means(group, ["modification_rate", "mean_action_delta", "not_triggered_rate", "plan_validity_rate"]),
                "llm_retry_count": int(group["llm_retry_count"].sum()),
            }
        )
        rows[-1].update(_llm_call_figures(data.logs, setting, policy))
    frame = pd.DataFrame(rows)
    columns = [
        Column("Setting", text("setting"), align="l"),
        Column("Policy", text("policy"), align="l"),
        Column("Steps", integer("steps")),
        Column("Audit Rate", cell("audit_rate", 3)),
        Column("Revision Given Audit", cell("revision_given_audit", 3)),
        Column("Modification Rate", cell("modification_rate", 3)),
        Column("Mean Action Δ", cell("mean_action_delta", 3), latex=r"Mean Action $\Delta$"),
        Column("Not Triggered", cell("not_triggered_rate", 3)),
    ]
    notes = []
    if (frame["llm_retry_count"] == 0).all():
        notes.append("The LLM retry count is zero for every row and is therefore not shown.")
    else:
        columns.append(Column("LLM Retries", integer("llm_retry_count")))
    if sources - {AGENTIC_LOG_FILE}:
        notes.append(f"Steps count {ACTIONS_FILE} rows where a group has no agentic log.")
    if frame["llm_calls"].sum() > 0:
        columns += LLM_CALL_COLUMNS
        notes.append(
            "LLM calls, latencies (median per call, seconds, as recorded) and tokens (mean per call) are read "
            "from agentic_logs.jsonl; a call answered from the record/replay cache counts with the recorded "
            "call's figures."
        )
    return ReportTable(
        key="llm_operations",
        label="tab:app-llm-ops",
        title=title,
        caption=(
            f'Detailed governance operation rates of the {layer} per agentic setting ("Main": RL+LLM; '
            '"No-physics": RL+LLM no-physics) and policy. Rates are pooled over the group\'s governance steps; '
            "revision given audit is revisions per audit."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
        notes=notes,
    )


LLM_CALL_COLUMNS = [
    Column("LLM Calls", integer("llm_calls")),
    Column("Planner Median s", cell("planner_median_s", 2)),
    Column("Auditor Median s", cell("auditor_median_s", 2)),
    Column("Prompt Tokens", cell("mean_prompt_tokens", 0)),
    Column("Completion Tokens", cell("mean_completion_tokens", 0)),
]


def _llm_call_figures(logs: pd.DataFrame, setting: str, policy: str) -> dict[str, float]:
    """Model calls of a group (planner and auditor), their median latencies and mean tokens.

    ``logs`` has the per-row call columns of :data:`~solarchain_eval.report.loading.LLM_CALL_FIELDS` (NaN: no call).
    """
    group = logs[(logs["setting"] == setting) & (logs["policy"] == policy)]

    def values(kind: str, name: str) -> pd.Series:
        return pd.to_numeric(group[f"{kind}_{name}"], errors="coerce").dropna()

    planner, auditor = values("planner", "latency_s"), values("auditor", "latency_s")
    prompt = pd.concat([values("planner", "input_tokens"), values("auditor", "input_tokens")])
    completion = pd.concat([values("planner", "output_tokens"), values("auditor", "output_tokens")])
    nan = float("nan")
    return {
        "llm_calls": len(planner) + len(auditor),
        "planner_median_s": float(planner.median()) if len(planner) else nan,
        "auditor_median_s": float(auditor.median()) if len(auditor) else nan,
        "mean_prompt_tokens": float(prompt.mean()) if len(prompt) else nan,
        "mean_completion_tokens": float(completion.mean()) if len(completion) else nan,
    }


def llm_triggers(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Appendix: post-hoc trigger rates and the Planner's mean thresholds."""
    layer = governance_layer(data.metrics, data.metadata)
    title = f"Detailed trigger diagnostics and mean Planner thresholds ({layer})"
    groups = _agentic_groups(data, "llm_triggers", title)
    if isinstance(groups, Skipped):
        return groups
    rows = [
        {
            "setting": AGENTIC_REWARD_LABELS[setting],
            "policy": policy_label(policy),
            **size_fields(group),
            **means(group, [c for c, _ in TRIGGER_COLUMNS]),
        }
        for setting, policy, group in groups
    ]
    frame = pd.DataFrame(rows)
    columns = [Column("Setting", text("setting"), align="l"), Column("Policy", text("policy"), align="l")]
    columns += [Column(header, cell(name, 3)) for name, header in TRIGGER_COLUMNS]
    return ReportTable(
        key="llm_triggers",
        label="tab:app-llm-triggers",
        title=title,
        caption=(
            f"Detailed post-hoc trigger diagnostics and mean Planner thresholds of the {layer}. Trigger columns "
            "report the "
            "fraction of logged steps satisfying each trigger condition, audited or not."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
    )


def _action(values) -> str:
    r, ell, b = (float(v) for v in values)
    return f"r={fixed(r, 3)}, l={fixed(ell, 3)}, b={fixed(b, 3)}"


def case_study(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """A representative audit trace from ``agentic_logs.jsonl`` (field/value rows)."""
    layer = governance_layer(data.metrics, data.metadata)
    title = f"Representative audit trace ({layer})"
    if data.logs.empty:
        return Skipped("case_study", title, "the run has no agentic_logs.jsonl (no agentic setting)")
    case, rule = select_case(data.logs, options)
    if case is None:
        return Skipped("case_study", title, f"the agentic logs hold no revised audit ({rule})")
    reason = case["reason"] if isinstance(case["reason"], str) and case["reason"] else "(none logged)"
    fields = [
        ("policy / setting", f"{policy_label(case['policy'])} / {setting_label(case['setting'])}"),
        ("Planner / auditor", layer),
        (
            "Episode and step",
            f"Episode {int(case['episode'])}, step {int(case['step'])}, hour {int(case['hour'])} "
            f"(run seed {int(case['run_seed'])})",
        ),
        (
            "Trigger context",
            f"raw violation {fixed(case['raw_violation_rate'], 2)}; gap {fixed(case['supply_gap'], 2)}; "
            f"static slippage {fixed(case['static_slippage'], 2)}",
        ),
        ("RL proposed action", _action(case["proposed_action"])),
        ("Audited final action", _action(case["final_action"])),
        ("Action delta", fixed(case["action_delta"], 3)),
        ("Auditor rationale", reason),
    ]
    frame = pd.DataFrame(fields, columns=["field", "value"])
    return ReportTable(
        key="case_study",
        label="tab:app-case-study",
        title=title,
        caption=(
            f"Representative audit trace of the {layer}, selected from agentic_logs.jsonl. The row records the market "
            "context, proposed RL action, audited final action, and action delta."
        ),
        columns=[
            Column("Field", text("field"), align="p{0.28\\linewidth}"),
            Column("Value", text("value"), align="p{0.62\\linewidth}"),
        ],
        data=frame,
        basis=f"n = 1 logged step, chosen among {len(data.logs)} agentic log steps.",
        notes=[f"Selected as {rule}."],
        wide=False,
    )
