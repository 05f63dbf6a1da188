"""Display names and row orders of policies and settings, as the paper prints them.

One home for every label the report shows, so tables and figures agree. The settings' labels and
the pairs the report compares (RL+LLM against RL, no-physics against physics) are read from the
settings' declarations (:class:`~solarchain_eval.evaluation.settings.Setting`'s ``label``,
``governance_label`` and ``compare_with``), not written here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from ..agents.checkpoints import TRAINABLE_ALGOS
from ..evaluation.settings import (
    ABLATION_CONTRAST,
    GOVERNANCE_CONTRAST,
    KNOWN_SETTINGS,
    SETTING_LABELS,
    SETTINGS,
    setting_pairs,
)
from ..tasks.registry import get_task

BASELINES = tuple(get_task().baselines())

#: Policy display names (the paper's spelling).
POLICY_DISPLAY = {
    "static": "Static",
    "random": "Random",
    "myopic": "Myopic",
    "ppo": "PPO",
    "sac": "SAC",
    "dqn": "DQN",
    "ppo-lag": "PPO-Lag",
}
#: The paper's policy order in the main tables and figures.
PAPER_POLICY_ORDER = ("static", "random", "myopic", "ppo", "sac", "dqn")
#: The paper's learned-policy order in the body tables (PPO, SAC, DQN).
LEARNED_ORDER = ("ppo", "sac", "dqn")
#: The package's own policies; any other name in a run is a user agent (an agent spec's).
BUILTIN_POLICIES = (*BASELINES, *TRAINABLE_ALGOS, "llm-agent")
#: What a user agent's display name says after its name.
USER_AGENT_SUFFIX = " (user agent)"

#: Setting labels of the four-setting tables ("Governance" / "Setting" columns of the body).
GOVERNANCE_LABELS = {name: KNOWN_SETTINGS[name].governance_label for name in SETTINGS}
#: Each agentic setting and the raw-RL setting it adds the layer to (its ``governance`` contrast;
#: for RL+LLM - RL deltas).
AGENTIC_BASE = {treated: base for base, treated, _ in setting_pairs(GOVERNANCE_CONTRAST, SETTINGS)}
#: Each physics-penalised setting and its no-physics ablation (the ``ablation`` contrast; for
#: no-physics - physics deltas).
ABLATION_PAIRS = {base: treated for base, treated, _ in setting_pairs(ABLATION_CONTRAST, SETTINGS)}
#: Row order of the four-setting appendix tables: each raw-RL setting, then the settings that govern
#: it (RL, RL+LLM, RL no-physics, RL+LLM no-physics).
GOVERNANCE_ORDER = tuple(
    name
    for base in SETTINGS
    if base not in AGENTIC_BASE
    for name in (base, *(treated for treated, of in AGENTIC_BASE.items() if of == base))
)
#: The LLM appendix tables name an agentic setting by its base's reward label ("Main" / "No-physics").
AGENTIC_REWARD_LABELS = {treated: KNOWN_SETTINGS[base].label for treated, base in AGENTIC_BASE.items()}

__all__ = [
    "SETTINGS",
    "SETTING_LABELS",
    "POLICY_DISPLAY",
    "PAPER_POLICY_ORDER",
    "LEARNED_ORDER",
    "GOVERNANCE_LABELS",
    "GOVERNANCE_ORDER",
    "AGENTIC_REWARD_LABELS",
    "AGENTIC_BASE",
    "ABLATION_PAIRS",
    "BUILTIN_POLICIES",
    "policy_label",
    "setting_label",
    "is_learned",
    "is_user_agent",
    "is_trained",
    "paper_order",
    "learned_order",
    "governance_layer",
    "llm_record",
]


def policy_label(policy: str) -> str:
    """Display name of ``policy`` (the paper's spelling; a user agent's name marked as such)."""
    if is_user_agent(policy):
        return f"{policy}{USER_AGENT_SUFFIX}"
    return POLICY_DISPLAY.get(policy, policy)


def setting_label(setting: str) -> str:
    """Display name of a setting as the appendix prints it ("Main", "LLM No-physics", ...; a
    registered setting's ``label``; any other name as it is)."""
    known = KNOWN_SETTINGS.get(setting)
    return known.label if known is not None else SETTING_LABELS.get(setting, setting)


def is_learned(policy: str) -> bool:
    """True for every policy that is not a rule baseline (PPO, SAC, DQN, any new learner and
    user agents): the policies the per-policy tables across settings list."""
    return policy not in BASELINES


def is_user_agent(policy: str) -> bool:
    """True for an agent evaluated from a user's spec (any name the package does not define)."""
    return policy not in BUILTIN_POLICIES


def is_trained(policy: str) -> bool:
    """True for the package's learned policies (not baselines, not user agents): what the
    pooled "RL" claims are about."""
    return is_learned(policy) and not is_user_agent(policy)


def paper_order(policies: Iterable[str]) -> list[str]:
    """``policies`` in the report's one order: Static, Random, Myopic, PPO, SAC, DQN, then others by name.

    Every table and figure lists policies in this order (the paper's appendix tables sort by name;
    the report does not, so a policy is found in the same place everywhere).
    """
    present = set(policies)
    known = [p for p in PAPER_POLICY_ORDER if p in present]
    return known + sorted(present - set(known))


def learned_order(policies: Iterable[str]) -> list[str]:
    """The learned policies among ``policies``: PPO, SAC, DQN first, then others by name."""
    learned = {p for p in policies if is_learned(p)}
    known = [p for p in LEARNED_ORDER if p in learned]
    return known + sorted(learned - set(known))


def llm_record(metadata: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The LLM settings recorded in run or paper metadata (``agentic.llm``: model, api, ...), if any.

    A ``decoding`` entry marks the local model server (``--llm-backend local``).
    """
    for holder in (metadata, metadata.get("grid") or {}, metadata.get("identity") or {}):
        agentic = holder.get("agentic") if isinstance(holder, Mapping) else None
        llm = agentic.get("llm") if isinstance(agentic, Mapping) else None
        if isinstance(llm, Mapping) and llm.get("model"):
            return llm
    return None


def _llm_model(metadata: Mapping[str, Any]) -> str | None:
    """The LLM model recorded in run or paper metadata (``agentic.llm.model``), if any."""
    llm = llm_record(metadata)
    return str(llm["model"]) if llm is not None else None


def governance_layer(metrics: Any, metadata: Mapping[str, Any]) -> str:
    """The planner and auditor that governed the agentic rollouts, as tables name them.

    E.g. "rule planner, rule auditor" or "llm:gpt-4o planner, oracle auditor" (from the
    ``planner`` and ``auditor`` columns of ``metrics.csv`` and the model in the metadata); several
    kinds are joined with "/"; "Planner/Auditor layer" when the columns are absent.
    """
    agentic = metrics[metrics["setting"].isin(list(AGENTIC_BASE))] if "setting" in metrics else metrics
    if agentic.empty or not {"planner", "auditor"} <= set(agentic.columns):
        return "Planner/Auditor layer"
    model = _llm_model(metadata)

    def kinds(column: str) -> str:
        names = sorted({str(k) for k in agentic[column].dropna()})
        return "/".join(f"llm:{model}" if k == "llm" and model else k for k in names) or "unknown"

    return f"{kinds('planner')} planner, {kinds('auditor')} auditor"
