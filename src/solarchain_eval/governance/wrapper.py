"""The Planner/Auditor layer as a policy wrapper around any base policy (evaluation only).

:class:`GovernedPolicy` uses the rollout hooks, so ``experiments.rollout.run_episode`` drives
it like any policy: ``begin_episode`` asks the planner for the episode's plan, ``act`` decodes
the base policy's proposal, bounds it, runs the scheduler and (if selected) the auditor, and
returns the final action re-encoded to [0, 1]^3; ``observe`` records the executed action;
``end_episode`` returns the per-step log rows and the episode's agentic metrics.

The wrapper always acts in continuous mode (a discrete base policy's index is decoded with the
env's discrete table), as the original release did.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..agents.base import Policy
from ..llm.errors import CallSite
from ..market.actions import DiscreteActions, initial_action
from ..market.observation import OBS_GAP, OBS_SLIPPAGE, OBS_VIOLATION, OBSERVATION_NAMES
from .auditor import Auditor, StepContext
from .controls import FixedScheduler, SchedulerControls
from .counterfactual import CounterfactualEvaluator, diagnostics_row
from .metrics import episode_agentic_metrics
from .planner import Planner, episode_context
from .scheduler import AuditScheduler, action_delta, audit_budget, bound_action, hard_reasons, kappa, soft_trigger
from .schemas import as_f32_list

#: The previous step's outcome shown to the auditor (``info`` keys).
RECENT_FIELDS = (
    "reward",
    "matched_energy_MWh",
    "unmet_demand_MWh",
    "liquidity",
    "token_price",
    "slippage",
    "physics_violation_rate",
    "artificial_liquidity_MWh",
)
_HOOKS = ("begin_episode", "observe", "end_episode")

#: Keys of the dict ``end_episode`` returns (merged into ``EpisodeResult.extras``): the
#: episode's agentic metrics (extra ``metrics.csv`` columns) and its step log rows.
EXTRA_METRICS_KEY = "agentic_metrics"
EXTRA_LOG_KEY = "agentic_log"
#: Key of the episode's counterfactual diagnostics rows (with ``diagnostics=True`` only).
EXTRA_DIAGNOSTICS_KEY = "governance_diagnostics"


class GovernedPolicy:
    """A base policy behind the Planner/Auditor scheduler (docs/planner_auditor.md#scheduler).

    Parameters
    ----------
    base : Policy
        Any policy (continuous or discrete); its name is kept.
    planner : Planner
    auditor : Auditor
        An auditor with a ``select_steps`` method (the ``always-audit`` and ``random`` controls)
        chooses the audited steps itself instead of the scheduler.
    controls : SchedulerControls, optional
        Trigger ablation and budget/cooldown overrides (docs/governance.md#controls).
    diagnostics : bool
        Also record the counterfactual outcome of the proposal, ā and the final action at every
        step (docs/governance.md); the executed trajectory is the same either way.
    """

    action_mode = "continuous"
    #: The planner reads the episode's hours ahead and the auditor evaluates counterfactual steps:
    #: the runner hands this wrapper the env (:func:`~solarchain_eval.agents.base.is_privileged`).
    privileged = True

    def __init__(
        self,
        base: Policy,
        planner: Planner,
        auditor: Auditor,
        controls: SchedulerControls | None = None,
        diagnostics: bool = False,
    ) -> None:
        self.base = base
        self.name = base.name
        self.planner = planner
        self.auditor = auditor
        self.controls = controls if controls is not None else SchedulerControls()
        self.diagnostics = bool(diagnostics)
        self._diagnostics_rows: list[dict[str, Any]] = []
        self._run_seed = 0
        self._rows: list[dict[str, Any]] = []
        self._base_hooks = {hook: getattr(base, hook, None) for hook in _HOOKS}

    # --- Policy protocol ----------------------------------------------------------------------
    def begin_run(self, run_seed: int) -> None:
        self._run_seed = int(run_seed)
        hook = getattr(self.base, "begin_run", None)
        if hook is not None:
            hook(run_seed)

    def begin_episode(self, *, env: Any, episode: int, run_seed: int, episode_seed: int, start_hour: int) -> None:
        self._env = env
        self._codec = env.codec
        self._episode = int(episode)
        self._run_seed = int(run_seed)
        self._decode = _proposal_decoder(env, self.base.action_mode)
        self._steps = int(env.episode_steps)
        site = CallSite("planner", self.name, self._run_seed, self._episode, None)
        outcome = self.planner.plan(episode_context(env, int(start_hour)), site)
        self._plan = outcome.plan
        self._plan_log = {**outcome.plan.to_log(), "llm": outcome.llm}
        self._start_scheduler()
        m = env.config.market
        self._previous = initial_action(m)  # a_prev at reset, as the env starts from it
        self._recent: dict[str, float] | None = None
        self._step = 0
        self._rows = []
        self._diagnostics_rows = []
        self._evaluate = CounterfactualEvaluator(env)
        self._pending: dict[str, Any] | None = None
        self._planner_retries = int((outcome.llm or {}).get("retries", 0))
        hook = self._base_hooks["begin_episode"]
        if hook is not None:  # the base policy gets the public context only, as without the layer
            hook(episode=episode, run_seed=run_seed, episode_seed=episode_seed, start_hour=start_hour)

    def _start_scheduler(self) -> None:
        """The episode's budget and scheduler (plan, overrides, or the auditor's own step choice)."""
        plan, controls = self._plan, self.controls
        max_audits = plan.max_audits_per_episode if controls.max_audits is None else controls.max_audits
        cooldown = plan.cooldown_steps if controls.cooldown_steps is None else controls.cooldown_steps
        self._budget = audit_budget(max_audits, plan.target_audit_rate, self._steps)
        select = getattr(self.auditor, "select_steps", None)
        if select is None:
            self._scheduler: AuditScheduler | FixedScheduler = AuditScheduler(self._budget, cooldown)
            return
        chosen = select(
            steps=self._steps, budget=self._budget, run_seed=self._run_seed, episode=self._episode, policy=self.name
        )
        self._scheduler = FixedScheduler(frozenset(chosen))

    def act(self, observation: np.ndarray) -> np.ndarray:
        plan, step = self._plan, self._step
        proposed = self._decode(self.base.act(observation))
        bounded = bound_action(proposed, plan, self._codec)
        violation = float(observation[OBS_VIOLATION])
        gap = float(observation[OBS_GAP])
        slippage = float(observation[OBS_SLIPPAGE])
        k = kappa(bounded, self._previous)
        reasons, soft = self.controls.triggers_used(hard_reasons(violation, gap, slippage, plan), soft_trigger(k, plan))
        self._evaluate.new_step()
        decision = self._scheduler.step(step, bool(reasons), soft)
        final, verdict, reason, llm = bounded, None, None, None
        if decision.audited:
            context = StepContext(
                step=step,
                hour=(self._env.episode_start_hour + step) % 24,
                observation={name: float(v) for name, v in zip(OBSERVATION_NAMES, observation, strict=True)},
                violation_rate=violation,
                supply_gap=gap,
                static_slippage=slippage,
                bounded_action=bounded,
                previous_action=self._previous,
                kappa=k,
                plan=plan,
                hard_reasons=tuple(reasons),
                soft_trigger=soft,
                recent=self._recent,
                counterfactual=self._evaluate,
            )
            outcome = self.auditor.audit(context, CallSite("auditor", self.name, self._run_seed, self._episode, step))
            final, verdict, reason, llm = outcome.final_action, outcome.decision, outcome.reason, outcome.llm
        self._pending = {
            "step": step,
            "absolute_hour": None,
            "hour": None,
            "raw_violation_rate": violation,
            "supply_gap": gap,
            "static_slippage": slippage,
            "kappa": k,
            "hard_trigger": bool(reasons),
            "soft_trigger": soft,
            "hard_reasons": reasons,
            "audited": decision.audited,
            "skip_reason": decision.skip_reason,
            "plan": self._plan_log,
            "proposed_action": as_f32_list(proposed),
            "bounded_action": as_f32_list(bounded),
            "final_action": as_f32_list(final),
            "executed_action": None,
            "decision": verdict,
            "action_delta": action_delta(final, proposed),
            "reason": reason,
            "audits_used": decision.audits_used,
            "audit_budget": self._budget,
            "llm": llm,
        }
        if self.diagnostics:
            self._diagnostics_rows.append(diagnostics_row(self._pending, self._evaluate, proposed, bounded, final))
        return self._codec.encode(*final)

    def observe(self, info: dict[str, Any]) -> None:
        row = self._pending
        if row is None:
            raise RuntimeError("observe() called without a preceding act()")
        executed = (info["reward_ratio"], info["liquidity_ratio"], info["burn_rate"])
        row["absolute_hour"] = int(info["absolute_hour"])
        row["hour"] = int(info["hour"])
        row["executed_action"] = as_f32_list(executed)
        self._rows.append(row)
        self._pending = None
        self._previous = tuple(float(v) for v in executed)
        self._recent = {name: float(info[name]) for name in RECENT_FIELDS}
        self._step += 1
        hook = self._base_hooks["observe"]
        if hook is not None:
            hook(info)

    def end_episode(self) -> dict[str, Any]:
        metrics = episode_agentic_metrics(
            self._rows,
            plan=self._plan,
            budget=self._budget,
            steps=self._steps,
            planner=self.planner.kind,
            auditor=self.auditor.kind,
            planner_retries=self._planner_retries,
        )
        extras: dict[str, Any] = {}
        hook = self._base_hooks["end_episode"]
        if hook is not None:
            extras.update(hook() or {})
        # The base policy's own metrics columns (the LLM agent's calls) follow the layer's.
        base_metrics = extras.get(EXTRA_METRICS_KEY, {})
        metrics = {**metrics, **{k: v for k, v in base_metrics.items() if k not in metrics}}
        extras.update({EXTRA_METRICS_KEY: metrics, EXTRA_LOG_KEY: self._rows})
        if self.diagnostics:
            extras[EXTRA_DIAGNOSTICS_KEY] = self._diagnostics_rows
        return extras


def _proposal_decoder(env: Any, action_mode: str) -> Callable[[Any], tuple[float, float, float]]:
    """Decode a base-policy action to market units (float32 values), by the base's mode."""
    if action_mode == "discrete":
        return DiscreteActions.from_codec(env.codec, env.config.discrete_levels).decode
    if action_mode != "continuous":
        raise ValueError(f"unknown action mode {action_mode!r}")
    return env.codec.decode
