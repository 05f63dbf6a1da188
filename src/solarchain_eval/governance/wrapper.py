"""The Planner/Auditor layer as a policy wrapper around any base policy (evaluation only).

:class:`GovernedPolicy` uses the rollout hooks, so ``experiments.rollout.run_episode`` drives
it like any policy: ``begin_episode`` asks the planner for the episode's plan, ``act`` decodes
the base policy's proposal, bounds it, runs the scheduler and (if selected) the auditor, and
returns the final action re-encoded to [0, 1]^3; ``observe`` records the executed action;
``end_episode`` returns the per-step log rows and the episode's agentic metrics.

The wrapper always acts in continuous mode (a discrete base policy's index is decoded with the
env's discrete table), as the original release did. Everything it reads from the market goes
through the market's governance view (:class:`~solarchain_eval.tasks.governance_view.GovernanceView`):
the codec, the risk signals in the observation, the episode's risk context, the
counterfactual oracle and the executed levers of each step.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..agents.base import Policy
from ..llm.errors import CallSite
from ..tasks.governance_view import GovernanceView
from .auditor import Auditor, StepContext
from .controls import FixedScheduler, SchedulerControls
from .counterfactual import CounterfactualEvaluator, diagnostics_row
from .metrics import episode_agentic_metrics
from .planner import Planner, episode_context
from .scheduler import AuditScheduler, action_delta, audit_budget, bound_action, hard_reasons, kappa, soft_trigger
from .schemas import as_f32_list
from .view import default_view, resolve_view


def __getattr__(name: str) -> Any:
    # The default task's outcome fields shown to the auditor, kept under their old name.
    if name == "RECENT_FIELDS":
        return default_view().recent_fields
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    view : GovernanceView, optional
        The market as the layer sees it; None: the default task's view of the env's config (the
        solar market), resolved at each episode's start.
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
        view: GovernanceView | None = None,
    ) -> None:
        self.view = view
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
        view = self._view = self.view if self.view is not None else resolve_view(env.config)
        self._codec = view.codec
        self._observation_names = view.observation_names
        self._episode = int(episode)
        self._run_seed = int(run_seed)
        self._decode = view.proposal_decoder(env, self.base.action_mode)
        site = CallSite("planner", self.name, self._run_seed, self._episode, None)
        context = episode_context(env, int(start_hour), view)
        self._steps = context.episode_steps
        outcome = self.planner.plan(context, site)
        self._plan = outcome.plan
        self._plan_log = {**outcome.plan.to_log(), "llm": outcome.llm}
        self._start_scheduler()
        self._previous = view.initial_action(env)  # a_prev at reset, as the env starts from it
        self._recent: dict[str, float] | None = None
        self._step = 0
        self._rows = []
        self._diagnostics_rows = []
        self._evaluate = CounterfactualEvaluator(env, view)
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
        violation, gap, slippage = self._view.risk_signals(observation)
        k = kappa(bounded, self._previous)
        reasons, soft = self.controls.triggers_used(hard_reasons(violation, gap, slippage, plan), soft_trigger(k, plan))
        self._evaluate.new_step()
        decision = self._scheduler.step(step, bool(reasons), soft)
        final, verdict, reason, llm = bounded, None, None, None
        if decision.audited:
            context = StepContext(
                step=step,
                hour=self._view.hour_of_day(self._env, step),
                observation={name: float(v) for name, v in zip(self._observation_names, observation, strict=True)},
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
        self._sent = self._codec.encode(*final)
        return self._sent

    def observe(self, info: dict[str, Any]) -> None:
        row = self._pending
        if row is None:
            raise RuntimeError("observe() called without a preceding act()")
        view = self._view
        executed = view.executed_action(info, self._sent)
        row["absolute_hour"], row["hour"] = view.step_hours(self._env, self._step, info)
        row["executed_action"] = as_f32_list(executed)
        self._rows.append(row)
        self._pending = None
        self._previous = tuple(float(v) for v in executed)
        self._recent = {name: float(info[name]) for name in view.recent_fields}
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
