"""Structured outputs of the Planner, the Auditor and the LLM agent, and their validation (docs/planner_auditor.md#schemas).

The pydantic models below are what a model must return; the JSON schema sent to it is the
one the OpenAI SDK derives from them in strict mode (see :func:`~solarchain_eval.llm.response_format.response_format`). Parsing is
strict (extra or missing fields, wrong types, NaN and infinities are errors). Validation then
turns a parsed output into the values that may touch the market: every number is clipped to
the benchmark's ranges (each clip is reported as a :class:`ClipEvent`), the auditor's action is
sanitised with the market's lever codec (:class:`~solarchain_eval.tasks.governance_view.LeverCodec`;
for the solar market including α + ℓ ≤ 0.98), and free text is length-capped and only ever logged.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, create_model

from ..tasks.governance_view import LeverCodec
from .view import default_view

#: Maximum lengths of the free-text fields (characters); longer text is cut and logged.
GOVERNANCE_MODE_MAX_CHARS = 64
TEXT_MAX_CHARS = 2000
#: ``maxLength`` of the free-text fields in the ``json_object`` schema: a grammar-constrained
#: local model otherwise runs on in them until the token budget ends (see docs/llm.md), and
#: every character is a token to generate.
SCHEMA_TEXT_MAX_CHARS = {"governance_mode": 32, "rationale": 64, "reason": 64}

#: Audit-policy ranges (docs/planner_auditor.md#schemas; the two integer ranges end at the episode length).
VIOLATION_THRESHOLD_RANGE = (0.0, 1.0)
GAP_THRESHOLD_RANGE = (-1.0, 0.0)
JITTER_THRESHOLD_RANGE = (0.0, 3.0)
SLIPPAGE_THRESHOLD_RANGE = (0.0, 10.0)
TARGET_AUDIT_RATE_RANGE = (0.0, 1.0)

ACTION_FIELDS = ("reward_ratio", "liquidity_ratio", "burn_rate")
RiskLevel = Literal["low", "medium", "high", "unknown"]


class _StrictOutput(BaseModel):
    # strict: JSON types must match the schema exactly; NaN/inf are rejected as non-finite.
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)
    #: Read by :func:`~solarchain_eval.llm.response_format.response_format` for ``chat-json-object``.
    json_object_text_caps: ClassVar[dict[str, int]] = SCHEMA_TEXT_MAX_CHARS


class Bounds(_StrictOutput):
    low: float = Field(description="Lowest admissible value.")
    high: float = Field(description="Highest admissible value.")


class ActionBounds(_StrictOutput):
    reward_ratio: Bounds = Field(description="Bounds on the reward ratio α (benchmark range 0.05-0.65).")
    liquidity_ratio: Bounds = Field(description="Bounds on the liquidity ratio ℓ (benchmark range 0.20-0.95).")
    burn_rate: Bounds = Field(description="Bounds on the burn rate b (benchmark range 0-0.20).")


class AuditPolicy(_StrictOutput):
    violation_threshold: float = Field(
        description="Hard trigger: audit when the raw physics-violation rate exceeds this (0-1)."
    )
    gap_threshold: float = Field(
        description="Hard trigger: audit when the supply gap (verified - demand) / demand is below this (-1-0)."
    )
    jitter_threshold: float = Field(
        description="Soft trigger: audit when the L1 change from the previous executed action exceeds this (0-3)."
    )
    slippage_threshold: float = Field(
        description="Hard trigger: audit when the static market slippage exceeds this (0-10)."
    )
    max_audits_per_episode: int = Field(description="Budget for soft-triggered audits per 24-step episode (1-24).")
    target_audit_rate: float = Field(description="Target fraction of audited steps (0-1).")
    cooldown_steps: int = Field(description="Minimum steps between soft-triggered audits (0-24).")


class PlannerOutput(_StrictOutput):
    """What the Planner returns once per episode."""

    governance_mode: str = Field(description="A short label for the chosen governance stance.")
    action_bounds: ActionBounds
    audit_policy: AuditPolicy
    rationale: str = Field(description="Why these bounds and thresholds (logged, never executed).")


class ActionValues(_StrictOutput):
    reward_ratio: float
    liquidity_ratio: float
    burn_rate: float


class RiskAssessment(_StrictOutput):
    physics: RiskLevel
    liquidity: RiskLevel
    jitter: RiskLevel
    fairness: RiskLevel


class AuditorOutput(_StrictOutput):
    """What the Auditor returns for one audited step."""

    decision: Literal["approve", "revise"] = Field(
        description="approve keeps the bounded proposed action; revise executes final_action."
    )
    final_action: ActionValues = Field(description="The action to execute when revising (market units).")
    risk_assessment: RiskAssessment
    reason: str = Field(description="Why (logged, never executed).")


Levers = tuple[tuple[str, str], ...]  # (name, description) of each lever, in order


@functools.cache  # one pair of classes per set of levers: the same schemas (and cache keys) every call
def output_models(levers: Levers | None = None) -> tuple[type[PlannerOutput], type[AuditorOutput]]:
    """The Planner's and the Auditor's output models for a market's levers.

    ``levers`` None or the solar market's three names: :class:`PlannerOutput` and
    :class:`AuditorOutput` themselves. Other names: the same models with ``action_bounds`` and
    ``final_action`` holding one field per lever (each bounds field described by the lever's text).
    """
    if levers is None or tuple(name for name, _ in levers) == ACTION_FIELDS:
        return PlannerOutput, AuditorOutput
    bounds = create_model(
        "ActionBounds",
        __base__=_StrictOutput,
        **{name: (Bounds, Field(description=f"Bounds on {text}")) for name, text in levers},
    )
    values = create_model("ActionValues", __base__=_StrictOutput, **{name: (float, ...) for name, _ in levers})
    planner_fields, auditor_fields = PlannerOutput.model_fields, AuditorOutput.model_fields
    planner = create_model(
        "PlannerOutput",
        __base__=_StrictOutput,
        __doc__=PlannerOutput.__doc__,
        governance_mode=(str, planner_fields["governance_mode"]),
        action_bounds=(bounds, ...),
        audit_policy=(AuditPolicy, ...),
        rationale=(str, planner_fields["rationale"]),
    )
    auditor = create_model(
        "AuditorOutput",
        __base__=_StrictOutput,
        __doc__=AuditorOutput.__doc__,
        decision=(Literal["approve", "revise"], auditor_fields["decision"]),
        final_action=(values, auditor_fields["final_action"]),
        risk_assessment=(RiskAssessment, ...),
        reason=(str, auditor_fields["reason"]),
    )
    return planner, auditor  # type: ignore[return-value]


def action_bounds(model: type[PlannerOutput], bounds: list[tuple[float, float]]) -> Any:
    """The ``action_bounds`` value of ``model`` with one (low, high) pair per lever, in order."""
    fields = model.model_fields["action_bounds"].annotation.model_fields  # type: ignore[union-attr]
    return model.model_fields["action_bounds"].annotation(  # type: ignore[misc]
        **{name: Bounds(low=low, high=high) for name, (low, high) in zip(fields, bounds, strict=True)}
    )


class AgentAction(_StrictOutput):
    """This hour's action, in market units, each value inside its range."""

    # The docstring is the schema's description, which a hosted model reads. Build the class with
    # agent_action_model(): its fields carry the market's ranges as minimum and maximum, so the
    # schema bounds each number and a reply outside them fails validation.

    reward_ratio: float
    liquidity_ratio: float
    burn_rate: float


def __getattr__(name: str) -> Any:
    # The default task's lever descriptions, kept under their old name (they are the market's text).
    if name == "AGENT_FIELD_DESCRIPTIONS":
        return dict(default_view().prompts.lever_descriptions)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def agent_action_model(codec: LeverCodec, descriptions: Mapping[str, str] | None = None) -> type[AgentAction]:
    """:class:`AgentAction` with each field bounded to ``codec``'s range (``ge``/``le``).

    ``descriptions`` names the levers (field names, in order) and describes each (the market's
    :attr:`~solarchain_eval.tasks.governance_view.GovernancePrompts.lever_descriptions`; None:
    the default task's).
    """
    if descriptions is None:
        descriptions = default_view().prompts.lever_descriptions
    return _bounded_agent_action(tuple(codec.lo), tuple(codec.hi), tuple(descriptions.items()))


@functools.cache  # one class per range: the same schema (and cache keys) for every agent
def _bounded_agent_action(
    lo: tuple[float, ...], hi: tuple[float, ...], described: tuple[tuple[str, str], ...]
) -> type[AgentAction]:
    fields: dict[str, Any] = {
        name: (float, Field(ge=low, le=high, description=text))
        for (name, text), low, high in zip(described, lo, hi, strict=True)
    }
    # Other levers than the solar market's: the same strict model without its three fields.
    base = AgentAction if tuple(fields) == ACTION_FIELDS else _StrictOutput
    return create_model("AgentAction", __base__=base, __doc__=AgentAction.__doc__, **fields)


# --- validated forms -------------------------------------------------------------------------
@dataclass(frozen=True)
class ClipEvent:
    """One value changed by validation: ``field`` went from ``value`` to ``clipped_to``."""

    field: str
    value: Any
    clipped_to: Any

    def to_log(self) -> dict[str, Any]:
        return {"field": self.field, "value": self.value, "clipped_to": self.clipped_to}


@dataclass(frozen=True)
class Plan:
    """A validated plan: the bounds and audit policy in force for one episode."""

    governance_mode: str
    bounds: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    violation_threshold: float
    gap_threshold: float
    jitter_threshold: float
    slippage_threshold: float
    max_audits_per_episode: int
    target_audit_rate: float
    cooldown_steps: int
    rationale: str
    #: The levers' names, the keys of the logged bounds (the Planner's output's ``action_bounds`` fields).
    lever_names: tuple[str, str, str] = ACTION_FIELDS

    def to_log(self) -> dict[str, Any]:
        return {
            "governance_mode": self.governance_mode,
            "bounds": {name: list(pair) for name, pair in zip(self.lever_names, self.bounds, strict=True)},
            "audit_policy": {
                "violation_threshold": self.violation_threshold,
                "gap_threshold": self.gap_threshold,
                "jitter_threshold": self.jitter_threshold,
                "slippage_threshold": self.slippage_threshold,
                "max_audits_per_episode": self.max_audits_per_episode,
                "target_audit_rate": self.target_audit_rate,
                "cooldown_steps": self.cooldown_steps,
            },
            "rationale": self.rationale,
        }


@dataclass(frozen=True)
class AuditVerdict:
    """A validated auditor output: ``final_action`` is sanitised float32 (α, ℓ, b)."""

    decision: str
    final_action: tuple[float, float, float]
    risk_assessment: dict[str, str]
    reason: str


def _clip(field: str, value: float, low: float, high: float, events: list[ClipEvent]) -> float:
    clipped = min(max(value, low), high)
    if clipped != value:
        events.append(ClipEvent(field, value, clipped))
    return clipped


def _cap_text(field: str, text: str, limit: int, events: list[ClipEvent]) -> str:
    if len(text) <= limit:
        return text
    events.append(ClipEvent(field, f"<{len(text)} characters>", f"<{limit} characters>"))
    return text[:limit]


def validate_plan(output: PlannerOutput, codec: LeverCodec, episode_steps: int) -> tuple[Plan, list[ClipEvent]]:
    """Clip a parsed plan to the benchmark's ranges (docs/planner_auditor.md#schemas).

    Bounds are sorted (a swap is reported) and clipped to the action ranges; thresholds,
    budget, target rate and cooldown to the audit-policy ranges.
    """
    events: list[ClipEvent] = []
    bounds = []
    names = tuple(type(output.action_bounds).model_fields)
    for name, pair, low, high in zip(names, _bound_pairs(output.action_bounds), codec.lo, codec.hi, strict=True):
        lo, hi = pair
        if lo > hi:
            events.append(ClipEvent(f"action_bounds.{name}", [lo, hi], [hi, lo]))
            lo, hi = hi, lo
        bounds.append(
            (
                _clip(f"action_bounds.{name}.low", lo, low, high, events),
                _clip(f"action_bounds.{name}.high", hi, low, high, events),
            )
        )
    p = output.audit_policy
    plan = Plan(
        governance_mode=_cap_text("governance_mode", output.governance_mode, GOVERNANCE_MODE_MAX_CHARS, events),
        bounds=(bounds[0], bounds[1], bounds[2]),
        violation_threshold=_clip(
            "audit_policy.violation_threshold", p.violation_threshold, *VIOLATION_THRESHOLD_RANGE, events
        ),
        gap_threshold=_clip("audit_policy.gap_threshold", p.gap_threshold, *GAP_THRESHOLD_RANGE, events),
        jitter_threshold=_clip("audit_policy.jitter_threshold", p.jitter_threshold, *JITTER_THRESHOLD_RANGE, events),
        slippage_threshold=_clip(
            "audit_policy.slippage_threshold", p.slippage_threshold, *SLIPPAGE_THRESHOLD_RANGE, events
        ),
        max_audits_per_episode=int(
            _clip("audit_policy.max_audits_per_episode", p.max_audits_per_episode, 1, episode_steps, events)
        ),
        target_audit_rate=_clip(
            "audit_policy.target_audit_rate", p.target_audit_rate, *TARGET_AUDIT_RATE_RANGE, events
        ),
        cooldown_steps=int(_clip("audit_policy.cooldown_steps", p.cooldown_steps, 0, episode_steps, events)),
        rationale=_cap_text("rationale", output.rationale, TEXT_MAX_CHARS, events),
        lever_names=names,  # type: ignore[arg-type]
    )
    return plan, events


def _bound_pairs(bounds: ActionBounds) -> list[tuple[float, float]]:
    return [(b.low, b.high) for b in (getattr(bounds, name) for name in type(bounds).model_fields)]


def validate_audit(output: AuditorOutput, codec: LeverCodec) -> tuple[AuditVerdict, list[ClipEvent]]:
    """Sanitise the auditor's action (ranges and α + ℓ ≤ cap, float32) and cap its text."""
    events: list[ClipEvent] = []
    names = tuple(type(output.final_action).model_fields)
    raw = tuple(getattr(output.final_action, name) for name in names)
    clipped = [
        _clip(f"final_action.{name}", value, low, high, events)
        for name, value, low, high in zip(names, raw, codec.lo, codec.hi, strict=True)
    ]
    total = clipped[0] + clipped[1]
    if total > codec.max_total_allocation:
        events.append(ClipEvent(f"final_action.{names[0]}+{names[1]}", total, codec.max_total_allocation))
    final = codec.sanitize(*raw)
    verdict = AuditVerdict(
        decision=output.decision,
        final_action=final,
        risk_assessment=output.risk_assessment.model_dump(),
        reason=_cap_text("reason", output.reason, TEXT_MAX_CHARS, events),
    )
    return verdict, events


def as_f32_list(action: tuple[float, float, float] | np.ndarray) -> list[float]:
    """An action as a JSON-ready list of the float32 values (exact, as Python floats)."""
    return [float(np.float32(v)) for v in action]
