"""Step-level action distributions of the learned policies (executed actions from actions.csv)."""

from __future__ import annotations

import pandas as pd

from ...loading import ReportData
from ...naming import SETTINGS, is_learned, paper_order, policy_label, setting_label
from ...options import ReportOptions
from ...table_model import Column, ReportTable, Skipped, basis_sentence, fixed, text
from .common import percentile_fields, size_fields, sizes_of

ACTION_COLUMNS = (("reward_ratio", "Reward Ratio"), ("liquidity_ratio", "Liquidity Ratio"), ("burn_rate", "Burn Rate"))


def _distribution(name: str):
    return lambda r: f"{fixed(r[f'{name}_mean'], 3)} ({fixed(r[f'{name}_p05'], 3)}–{fixed(r[f'{name}_p95'], 3)})"


def action_distributions(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Mean and 5th–95th percentiles of α, ℓ, b per setting and learned policy."""
    title = "Step-level action distributions for learned policies"
    if data.actions.empty:
        return Skipped("action_distributions", title, "the run has no actions.csv")
    missing = [c for c, _ in ACTION_COLUMNS if c not in data.actions.columns]
    if missing:
        return Skipped("action_distributions", title, f"actions.csv lacks column(s) {', '.join(missing)}")
    steps = data.actions[data.actions["policy"].map(is_learned)].rename(columns={"episode_start_hour": "start_hour"})
    if steps.empty:
        return Skipped("action_distributions", title, "the run has no learned policies (only rule baselines)")
    rows = []
    for setting in SETTINGS:
        in_setting = steps[steps["setting"] == setting]
        for policy in paper_order(in_setting["policy"]):
            group = in_setting[in_setting["policy"] == policy]
            row = {"setting": setting_label(setting), "policy": policy_label(policy), **size_fields(group)}
            for name, _ in ACTION_COLUMNS:
                row |= percentile_fields(group[name].to_numpy(dtype=float), name)
            rows.append(row)
    frame = pd.DataFrame(rows)
    columns = [Column("Setting", text("setting"), align="l"), Column("Policy", text("policy"), align="l")]
    columns += [Column(header, _distribution(name)) for name, header in ACTION_COLUMNS]
    return ReportTable(
        key="action_distributions",
        label="tab:app-action-distributions",
        title=title,
        caption=(
            "Step-level action distributions for learned policies (executed actions). Each cell reports the mean "
            "with the 5th–95th percentile range in parentheses."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "steps"),
    )
