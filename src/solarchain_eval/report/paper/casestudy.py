"""Which logged audit step the case study shows (one rule for its table and its figures)."""

from __future__ import annotations

import pandas as pd

from ..options import ReportOptions


def revised_steps(logs: pd.DataFrame) -> pd.DataFrame:
    """Audited steps whose action the Auditor revised."""
    if logs.empty:
        return logs
    audited = logs["audited"].astype(bool)
    return logs[audited & (logs["decision"] == "revise")]


def select_case(logs: pd.DataFrame, options: ReportOptions) -> tuple[pd.Series | None, str]:
    """The representative audit trace and the rule that picked it.

    Rule: among revised steps of ``options.case_policy`` in ``options.case_setting`` (the paper's
    PPO under the no-physics LLM setting) — or of any policy and setting when that pair has
    none — the step with the largest action delta; ties go to the lowest (run seed, episode,
    step).

    Returns
    -------
    (step or None, rule text)
    """
    revised = revised_steps(logs)
    if revised.empty:
        return None, "no audited step was revised"
    preferred = revised[(revised["policy"] == options.case_policy) & (revised["setting"] == options.case_setting)]
    scope = f"{options.case_policy} in {options.case_setting}"
    if preferred.empty:
        preferred, scope = (
            revised,
            f"all policies and settings ({options.case_policy} in {options.case_setting} has no revised step)",
        )
    ranked = preferred.assign(_neg_delta=-preferred["action_delta"].astype(float)).sort_values(
        ["_neg_delta", "setting", "policy", "run_seed", "episode", "step"], kind="stable"
    )
    rule = f"the revised step with the largest action delta among {scope}; ties to the lowest run seed, episode, step"
    return ranked.drop(columns="_neg_delta").iloc[0], rule


def episode_steps(logs: pd.DataFrame, case: pd.Series) -> pd.DataFrame:
    """Every logged step of the case's episode, in step order."""
    same = (
        (logs["policy"] == case["policy"])
        & (logs["setting"] == case["setting"])
        & (logs["run_seed"] == case["run_seed"])
        & (logs["episode"] == case["episode"])
    )
    return logs[same].sort_values("step", kind="stable")
