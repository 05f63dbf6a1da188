"""Latency, CPU time, throughput and risk response of a Planner/Auditor model (``bench-llm``).

The calls come in the order an evaluation makes them: per simulated episode, one planner call
and then several auditor calls under that episode's plan, so a server's prompt cache helps as
much as it would in a run. Each call uses one of two situations: a calm one (no violations,
supply above demand, low slippage) and a risky one (violation rate 0.3, a 40 % shortfall, high
slippage), varied slightly from call to call (start hour, step, demand) so no two requests are
identical; the figures therefore also say whether the model's answers move with the risk
signals. Nothing is cached: every call reaches the endpoint.

The situations are the solar market's (its observation features and levers): the codec and the
feature names come from the solar task through the task interface (its governance view and
:func:`~solarchain_eval.tasks.base.observation_names_of`).
"""

from __future__ import annotations

import statistics
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..governance.auditor import LLMAuditor, StepContext
from ..governance.planner import EpisodeContext, LLMPlanner, RulePlanner
from ..llm.client import StructuredLLM
from ..llm.errors import CallSite, LLMError, LLMTransportError
from ..tasks.base import observation_names_of
from ..tasks.governance_view import LeverCodec, governance_view_of
from ..tasks.registry import DEFAULT_TASK, get_task

RISKS = ("calm", "risky")


def solar_codec() -> LeverCodec:
    """The solar market's lever codec at its default configuration (its governance view's)."""
    return governance_view_of(get_task(DEFAULT_TASK)).codec


def solar_observation_names() -> tuple[str, ...]:
    """The solar market's observation features, in order (the task's declaration)."""
    names = observation_names_of(get_task(DEFAULT_TASK))
    assert names is not None, "the solar task declares its observation features"
    return names


def episode_situation(risk: str, index: int = 0) -> EpisodeContext:
    """An episode context with ``calm`` or ``risky`` statistics (energies in MWh); ``index``
    varies the start hour and the demand a little."""
    risky = risk == "risky"
    stats = {
        "max_violation_rate": 0.3 if risky else 0.0,
        "mean_violation_rate": 0.12 if risky else 0.0,
        "min_supply_gap": -0.4 if risky else 0.15,
        "mean_supply_gap": -0.2 if risky else 0.3,
        "mean_static_slippage": 1.4 if risky else 0.2,
        "max_static_slippage": 3.0 if risky else 0.4,
        "mean_verified_supply_MWh": 80.0 if risky else 140.0,
        "max_verified_supply_MWh": 150.0 if risky else 210.0,
        "mean_demand_MWh": 110.0 + index,
        "hours_with_supply_shortfall": 14.0 if risky else 0.0,
    }
    return EpisodeContext(
        start_hour=index % 24,
        episode_steps=24,
        physics_penalty=True,
        max_violation_rate=stats["max_violation_rate"],
        min_supply_gap=stats["min_supply_gap"],
        mean_static_slippage=stats["mean_static_slippage"],
        statistics=stats,
    )


def step_situation(risk: str, codec: LeverCodec, step: int = 6, episode: int = 0) -> StepContext:
    """An audited step: ``calm`` (a jitter-only trigger) or ``risky`` (all hard triggers), under
    the rule planner's plan for a risky episode whatever the step's risk (a plan holds for a
    whole episode); ``step`` also sets the hour, and ``step`` and ``episode`` vary the liquidity."""
    risky = risk == "risky"
    plan = RulePlanner(codec).plan(episode_situation("risky"), CallSite("planner", "bench", 0, 0)).plan
    observation = dict.fromkeys(solar_observation_names(), 0.0)
    violation, gap, slippage = (0.3, -0.4, 1.4) if risky else (0.0, 0.2, 0.2)
    observation.update(
        hour_sin=1.0,
        verified_supply_MWh=80.0 if risky else 140.0,
        reported_supply_MWh=120.0 if risky else 140.0,
        pmax_MWh=150.0,
        supply_gap=gap,
        liquidity=500.0 + 10.0 * step + 100.0 * episode,
        token_price=1.0,
        raw_physics_record_rate=violation,
        static_slippage=slippage,
        prev_reward_ratio=0.3,
        prev_liquidity_ratio=0.5,
    )
    bounded = codec.sanitize(0.6, 0.35, 0.0) if risky else codec.sanitize(0.3, 0.5, 0.05)
    previous = codec.sanitize(0.3, 0.5, 0.05) if risky else codec.sanitize(0.1, 0.8, 0.05)
    return StepContext(
        step=step,
        hour=step % 24,
        observation=observation,
        violation_rate=violation,
        supply_gap=gap,
        static_slippage=slippage,
        bounded_action=bounded,
        previous_action=previous,
        kappa=float(sum(abs(a - b) for a, b in zip(bounded, previous, strict=True))),
        plan=plan,
        hard_reasons=("violation", "gap", "slippage") if risky else (),
        soft_trigger=not risky,
        recent=None,
    )


@dataclass
class KindFigures:
    """Per-kind results: latencies (s), server CPU time (s), tokens and the answers by situation."""

    latencies_s: list[float] = field(default_factory=list)
    cpu_s: list[float] = field(default_factory=list)
    prompt_tokens: list[int] = field(default_factory=list)
    completion_tokens: list[int] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    answers: dict[str, list[str]] = field(default_factory=lambda: {risk: [] for risk in RISKS})

    def summary(self) -> dict[str, Any]:
        lat = self.latencies_s
        tokens = sum(self.completion_tokens)
        return {
            "calls": len(lat) + len(self.failures),
            "valid": len(lat),
            "median_s": statistics.median(lat) if lat else None,
            "p90_s": float(np.percentile(lat, 90)) if lat else None,
            "median_cpu_s": statistics.median(self.cpu_s) if self.cpu_s else None,
            "tokens_per_s": tokens / sum(lat) if lat and sum(lat) > 0 else None,
            "mean_prompt_tokens": statistics.fmean(self.prompt_tokens) if self.prompt_tokens else None,
            "mean_completion_tokens": tokens / len(lat) if lat else None,
        }


def run_llm_bench(
    client: StructuredLLM,
    calls: int,
    *,
    audits_per_plan: int = 1,
    on_call: Callable[[], None] = lambda: None,
    cpu_seconds: Callable[[], float] | None = None,
) -> dict[str, KindFigures]:
    """``calls`` planner calls, each followed by ``audits_per_plan`` auditor calls.

    Planner calls alternate calm and risky episodes; within an episode the auditor calls
    alternate calm and risky steps. ``cpu_seconds`` (the server process's CPU time so far, when
    the server is ours) gives each call's CPU time. A call whose output fails validation counts
    as a failure (its message is kept); transport errors propagate.
    """
    codec = solar_codec()
    planner, auditor = LLMPlanner(client, codec), LLMAuditor(client, codec)
    figures = {"planner": KindFigures(), "auditor": KindFigures()}
    for i in range(calls):
        jobs: list[tuple[str, str, int]] = [("planner", RISKS[i % 2], i)]
        jobs += [("auditor", RISKS[j % 2], 1 + j) for j in range(audits_per_plan)]
        for kind, risk, step in jobs:
            site = CallSite(kind, "bench", 0, i, None if kind == "planner" else step)
            cpu_before = cpu_seconds() if cpu_seconds is not None else 0.0
            try:
                if kind == "planner":
                    outcome = planner.plan(episode_situation(risk, i), site)
                    p = outcome.plan
                    answer = f"{p.governance_mode} (violation>{p.violation_threshold:g}, gap<{p.gap_threshold:g})"
                    meta = outcome.llm
                else:
                    verdict = auditor.audit(step_situation(risk, codec, step, i), site)
                    answer, meta = verdict.decision, verdict.llm
            except LLMError as error:
                if isinstance(error, LLMTransportError):
                    raise
                figures[kind].failures.append(str(error))
                on_call()
                continue
            assert meta is not None
            fig = figures[kind]
            if cpu_seconds is not None:
                fig.cpu_s.append(cpu_seconds() - cpu_before)
            fig.latencies_s.append(float(meta["latency_s"]))
            fig.prompt_tokens.append(int(meta["input_tokens"] or 0))
            fig.completion_tokens.append(int(meta["output_tokens"] or 0))
            fig.answers[risk].append(answer)
            on_call()
    return figures
