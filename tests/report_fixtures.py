"""A small synthetic paper root that follows the run layout and the agentic contract exactly.

Six policies (baselines in the two raw settings, learned policies in all four), 2 run seeds ×
4 episodes with the paper's seed protocol (episode seed = run seed + episode, so the seeds
overlap), start day = (episode seed mod 3), 24 steps per episode, 2 cities. Agentic
per-episode metrics are derived from the generated logs the way the contract defines them, so
tests can check the report's log- and metrics-based numbers against each other.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd

from solarchain_eval.records_schema import AGENTIC_METRIC_NAMES, DIAGNOSTIC_NAMES, EPISODE_KEYS, METRIC_NAMES

SETTINGS = ("main", "no_physics", "llm", "llm_no_physics")
BASELINES = ("static", "random", "myopic")
LEARNED = ("ppo", "sac", "dqn")
RUN_SEEDS = (11, 12)
EPISODES = 4
STEPS = 24
CITIES = ("Alpha", "Beta")
METRICS = METRIC_NAMES  # the episode metrics every metrics.csv carries
REASONS = ("Violation rate exceeds audit threshold; tighten allocation.", "Supply gap is negative; raise liquidity.")


def start_hour(episode_seed: int) -> int:
    return 24 * (episode_seed % 3)


def _policies(setting: str) -> tuple[str, ...]:
    return LEARNED if setting.startswith("llm") else BASELINES + LEARNED


def _log_steps(rng: np.random.Generator, policy: str, setting: str, seed: int, episode: int) -> list[dict]:
    steps = []
    start = start_hour(seed + episode)
    for step in range(STEPS):
        proposed = [round(float(v), 6) for v in rng.uniform(0.0, 1.0, 3)]
        hard = bool(rng.random() < 0.3)
        soft = bool(rng.random() < 0.3)
        audited = (hard or soft) and bool(rng.random() < 0.8)
        revise = audited and bool(rng.random() < 0.85)
        final = [round(float(v), 6) for v in rng.uniform(0.0, 1.0, 3)] if revise else list(proposed)
        delta = float(np.float32(sum(abs(a - b) for a, b in zip(final, proposed, strict=True))))
        steps.append(
            {
                "policy": policy,
                "setting": setting,
                "run_seed": seed,
                "episode": episode,
                "episode_seed": seed + episode,
                "step": step,
                "absolute_hour": start + step,
                "hour": (start + step) % 24,
                "raw_violation_rate": round(float(rng.uniform(0, 0.3)), 4),
                "supply_gap": round(float(rng.normal(0, 1)), 4),
                "static_slippage": round(float(rng.uniform(0, 1)), 4),
                "kappa": round(float(rng.uniform(0, 1.5)), 4),
                "hard_trigger": hard,
                "soft_trigger": soft,
                "hard_reasons": ["violation"] if hard else [],
                "audited": audited,
                "skip_reason": None if audited or not (hard or soft) else "budget",
                "plan": {
                    "governance_mode": "rule_balanced",
                    "bounds": {"reward_ratio": [0.05, 0.65], "liquidity_ratio": [0.2, 0.95], "burn_rate": [0.0, 0.2]},
                    "audit_policy": {"max_audits": 6},
                    "rationale": "fixture",
                },
                "proposed_action": proposed,
                "bounded_action": proposed,
                "final_action": final,
                "executed_action": final,
                "decision": ("revise" if revise else "approve") if audited else None,
                "action_delta": delta,
                "reason": REASONS[step % 2] if audited else None,
                "audits_used": 0,
                "audit_budget": 6,
                "llm": None,
            }
        )
    return steps


def _agentic_metrics(rng: np.random.Generator, steps: list[dict]) -> dict:
    """The agentic columns of one episode, in the record schema's order (a missing or extra one fails)."""
    audits = sum(s["audited"] for s in steps)
    revisions = sum(s["decision"] == "revise" for s in steps)
    values = {
        "plan_validity_rate": 1.0,
        "audit_rate": audits / STEPS,
        "revision_rate": revisions / max(audits, 1),
        "modification_rate": sum(s["final_action"] != s["proposed_action"] for s in steps) / STEPS,
        "mean_action_delta": sum(s["action_delta"] for s in steps) / STEPS,
        "llm_retry_count": 0,
        "hard_trigger_rate": sum(s["hard_trigger"] for s in steps) / STEPS,
        "soft_trigger_rate": sum(s["soft_trigger"] for s in steps) / STEPS,
        "not_triggered_rate": sum(not (s["hard_trigger"] or s["soft_trigger"]) for s in steps) / STEPS,
        "physics_trigger_rate": int(rng.integers(0, 25)) / STEPS,
        "gap_trigger_rate": int(rng.integers(0, 25)) / STEPS,
        "slippage_trigger_rate": int(rng.integers(0, 25)) / STEPS,
    }
    rng.integers(0, 25)  # the dropped jitter_trigger_rate's draw, kept so the later draws stay the same
    values.update(
        {
            "plan_violation_threshold": float(rng.uniform(0.1, 0.2)),
            "plan_gap_threshold": float(rng.uniform(-0.2, 0.0)),
            "plan_jitter_threshold": float(rng.uniform(0.1, 0.3)),
            "plan_slippage_threshold": float(rng.uniform(2.0, 4.0)),
            "plan_audit_budget": 6,
            "governance_mode": "rule_balanced",
            "planner": "rule",
            "auditor": "rule",
        }
    )
    extra = set(values) - set(AGENTIC_METRIC_NAMES)
    assert not extra, f"fixture columns outside the record schema: {sorted(extra)}"
    return {name: values[name] for name in AGENTIC_METRIC_NAMES}


def _diagnostics(rng: np.random.Generator, logs: list[dict]) -> pd.DataFrame:
    """Counterfactual step records for the logged steps (governance_diagnostics.csv columns)."""
    rows = []
    for s in logs:
        least = float(rng.uniform(0.0, 0.05))
        proposal = least + float(rng.exponential(0.03))
        final = proposal - (float(rng.uniform(0.0, proposal - least)) if s["decision"] == "revise" else 0.0)
        reward = float(rng.normal())
        row = {k: s[k] for k in ("policy", "setting", "run_seed", "episode", "episode_seed")}
        row |= {"start_hour": s["absolute_hour"] - s["step"], "planner": "rule", "auditor": "rule", "step": s["step"]}
        row |= {"audited": s["audited"], "decision": s["decision"], "hard_trigger": s["hard_trigger"]}
        row |= {"soft_trigger": s["soft_trigger"]}
        for role, cost, gain in (
            ("proposal", proposal, 0.0),
            ("bounded", proposal, 0.0),
            ("final", final, proposal - final),
        ):
            row |= {
                f"{role}_cost": cost,
                f"{role}_reward": reward + gain,
                f"{role}_artificial_liquidity_MWh": cost / 10,
                # the outcomes no table reads, consistent with the cost (no draws: the stream stays as it was)
                f"{role}_violation_rate": cost / 2,
                f"{role}_unsafe_backed_MWh": cost / 2,
                f"{role}_matched_energy_MWh": 100.0,
                f"{role}_slippage": 0.5,
                f"{role}_token_price": 1.0,
            }
        row["least_cost"] = least
        rows.append(row)
    return pd.DataFrame(rows, columns=[*EPISODE_KEYS, "planner", "auditor", *DIAGNOSTIC_NAMES])


def make_paper_root(root: Path, seed: int = 5) -> Path:
    """Write the synthetic paper root under ``root`` and return it."""
    rng = np.random.default_rng(seed)
    for setting in SETTINGS:
        metrics, actions, city_rows, logs = [], [], [], []
        for policy in _policies(setting):
            for run_seed in RUN_SEEDS:
                for episode in range(EPISODES):
                    episode_seed = run_seed + episode
                    row = {
                        "policy": policy,
                        "setting": setting,
                        "run_seed": run_seed,
                        "episode": episode,
                        "episode_seed": episode_seed,
                        "start_hour": start_hour(episode_seed),
                    }
                    row |= {name: float(rng.normal(0.5, 0.2)) for name in METRICS}
                    row["cumulative_reward"] = float(rng.normal(-23.0 if setting in ("main", "llm") else 0.3, 1.0))
                    if setting.startswith("llm"):
                        steps = _log_steps(rng, policy, setting, run_seed, episode)
                        logs += steps
                        row |= _agentic_metrics(rng, steps)
                    metrics.append(row)
                    for step in range(STEPS):
                        action = {
                            "reward_ratio": float(rng.uniform(0.05, 0.65)),
                            "liquidity_ratio": float(rng.uniform(0.2, 0.95)),
                            "burn_rate": float(rng.uniform(0, 0.2)),
                        }
                        hour = (row["start_hour"] + step) % 24
                        actions.append(
                            {k: row[k] for k in ("policy", "setting", "run_seed", "episode", "episode_seed")}
                            | {
                                "step": step,
                                "reward": float(rng.normal()),
                                "absolute_hour": row["start_hour"] + step,
                                "episode_start_hour": row["start_hour"],
                                "hour": hour,
                            }
                            | action
                        )
                        for city in CITIES:
                            city_rows.append(
                                {k: row[k] for k in ("policy", "setting", "run_seed", "episode")}
                                | {
                                    "step": step,
                                    "absolute_hour": row["start_hour"] + step,
                                    "hour": hour,
                                    "city": city,
                                    "city_reward": float(rng.uniform(0, 0.02)),
                                }
                                | action
                            )
        folder = root / "combined" / setting
        folder.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(metrics).to_csv(folder / "metrics.csv", index=False)
        pd.DataFrame(actions).to_csv(folder / "actions.csv", index=False)
        pd.DataFrame(city_rows).to_csv(folder / "city_hour_policy.csv", index=False)
        if logs:
            (folder / "agentic_logs.jsonl").write_text("".join(json.dumps(s) + "\n" for s in logs), encoding="utf-8")
            # its own stream, so the other files' values are those of the fixture without it
            _diagnostics(np.random.default_rng([seed, 1]), logs).to_csv(
                folder / "governance_diagnostics.csv", index=False
            )
    return write_paper_metadata(root)


def write_paper_metadata(root: Path) -> Path:
    """(Re)write ``paper_metadata.json`` with the hashes of the combined files as they are now."""
    (root / "paper_metadata.json").write_text(
        json.dumps(
            {
                "grid": {"settings": list(SETTINGS)},
                "dataset": {"data_dir": str(root / "no-such-data"), "files": {"market_liquidity.csv": "0" * 64}},
                "combined_sha256": {  # as the grid records them, so that the report trusts these files
                    s: {
                        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
                        for p in sorted((root / "combined" / s).iterdir())
                    }
                    for s in SETTINGS
                },
            }
        ),
        encoding="utf-8",
    )
    return root
