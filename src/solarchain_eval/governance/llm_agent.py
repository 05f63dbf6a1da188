"""The LLM as the agent: the model chooses (α, ℓ, b) every hour through a strict JSON schema.

:class:`LLMAgent` is a continuous policy. Every step it sends the fixed agent prompt
(:func:`~solarchain_eval.governance.prompts.agent_messages`) with the action ranges, the step,
the hour of day, the observation by name and the previous hour's outcome, and asks for an
:class:`~solarchain_eval.governance.schemas.AgentAction` whose numbers the schema bounds to the
market's ranges. A reply that does not validate (out of range, malformed) is asked again up to
``max_retries`` times with the problem named, then fails the run with a typed
:class:`~solarchain_eval.llm.errors.LLMError` naming the policy, episode and step. The action is
encoded to [0, 1]³ with the market's lever codec (for the solar market this also applies the
α + ℓ cap), as any policy that thinks in market units. The market's governance view supplies the
levers, the observation's names and the prompt's domain text.

Fairness: the agent sees what any policy sees, no more. Its hooks take no env (the rollout passes
the env only to hooks that declare it): only the observations, the previous step's ``info`` and
the public context (run seed, episode, episode seed, start hour). Its model calls go through the
Planner/Auditor's client (:class:`~solarchain_eval.llm.client.StructuredLLM`: the same settings,
typed errors and record/replay cache), and each episode's calls, tokens, latency, retries and
rejected replies become ``metrics.csv`` columns (:data:`~solarchain_eval.records_schema.LLM_AGENT_METRIC_NAMES`)
through the extras key the wrapper uses.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from ..llm.client import StructuredLLM
from ..llm.errors import CallSite
from .factory import LLMOptions
from .planner import benchmark_ranges
from .prompts import agent_messages
from .schemas import agent_action_model
from .view import resolve_view
from .wrapper import EXTRA_METRICS_KEY

LLM_AGENT_NAME = "llm-agent"
#: The call site kind in error messages ("LLM agent for policy ..., step ...").
AGENT_SITE_KIND = "agent"


def _sig(value: float) -> float:
    """Six significant digits: short, deterministic prompts."""
    return float(f"{value:.6g}")


class LLMAgent:
    """A policy whose every action is the model's structured reply.

    Parameters
    ----------
    client : StructuredLLM
        The endpoint client (its settings, cache and typed errors); the agent does not close it
        (see :func:`open_llm_agent` for one that does).
    view : GovernanceView or config
        The market's governance view (its levers, ranges, observation names and prompt text); a
        benchmark config or its market section stands for the default task's view of it.
    name : str
        The ``policy`` column of the records.
    """

    action_mode = "continuous"

    def __init__(self, client: StructuredLLM, view: Any, *, name: str = LLM_AGENT_NAME) -> None:
        self.client = client
        self.name = name
        self.view = resolve_view(view)
        self.codec = self.view.codec
        self.prompts = self.view.prompts
        self.output_type = agent_action_model(self.codec, self.prompts.lever_descriptions)
        self._levers = tuple(self.prompts.lever_descriptions)
        self._owns_client = False
        self._run_seed = 0
        self._episode = 0
        self._start_hour = 0
        self._step = 0
        self._previous: dict[str, float] | None = None
        self._calls: list[dict[str, Any]] = []

    # --- Policy protocol ----------------------------------------------------------------------
    def begin_run(self, run_seed: int) -> None:
        self._run_seed = int(run_seed)

    def begin_episode(self, *, episode: int, run_seed: int, episode_seed: int, start_hour: int) -> None:
        """Start an episode; the public context only (no env, no hourly table)."""
        self._episode = int(episode)
        self._run_seed = int(run_seed)
        self._start_hour = int(start_hour)
        self._step = 0
        self._previous = None
        self._calls = []

    def act(self, observation: np.ndarray) -> np.ndarray:
        site = CallSite(AGENT_SITE_KIND, self.name, self._run_seed, self._episode, self._step)
        reply = self.client.request(
            agent_messages(self.context(observation), self.prompts),
            self.output_type,
            site,
            invalid_retries=self.client.settings.max_retries,
        )
        self._calls.append(reply.meta)
        action = reply.output
        return self.codec.encode(*(getattr(action, lever) for lever in self._levers))

    def observe(self, info: dict[str, Any]) -> None:
        self._previous = {name: _sig(float(info[name])) for name in self.prompts.agent_outcome_units}
        self._step += 1

    def end_episode(self) -> dict[str, Any]:
        """The episode's LLM operations as extra ``metrics.csv`` columns."""
        return {EXTRA_METRICS_KEY: llm_agent_metrics(self._calls)}

    def close(self) -> None:
        """Release the client when this agent owns it (:func:`open_llm_agent`)."""
        if self._owns_client:
            self.client.close()

    # --- helpers ------------------------------------------------------------------------------
    def context(self, observation: np.ndarray) -> dict[str, Any]:
        """What the prompt shows this step: run-constant keys first (a shared prompt prefix)."""
        named = dict(zip(self.view.observation_names, observation.tolist(), strict=True))
        return {
            "action_ranges": benchmark_ranges(self.codec, self._levers),
            "step": self._step,
            "hour_of_day": (self._start_hour + self._step) % 24,
            "observation": {name: _sig(named[name]) for name in self.prompts.agent_observation_units},
            "previous_hour_outcome": self._previous,
        }

    def __deepcopy__(self, memo: dict[int, Any]) -> LLMAgent:
        # A private copy (evaluate --llm-concurrency runs a run seed's episodes on one) shares the
        # client: its HTTP connections and cache are safe to use from several threads.
        twin = copy.copy(self)
        twin._owns_client = False
        twin._calls = []
        return twin

    def __enter__(self) -> LLMAgent:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def llm_agent_metrics(calls: list[dict[str, Any]]) -> dict[str, Any]:
    """The episode's :data:`~solarchain_eval.records_schema.LLM_AGENT_METRIC_NAMES` from its calls'
    metadata (tokens a server did not report count as 0)."""
    latencies = [float(c["latency_s"]) for c in calls]
    return {
        "llm_agent_call_count": len(calls),
        "llm_agent_input_tokens": sum(int(c["input_tokens"] or 0) for c in calls),
        "llm_agent_output_tokens": sum(int(c["output_tokens"] or 0) for c in calls),
        "llm_agent_latency_s": round(sum(latencies), 6),
        "llm_agent_max_latency_s": max(latencies, default=0.0),
        "llm_agent_retry_count": sum(int(c["retries"]) for c in calls),
        "llm_agent_invalid_reply_count": sum(int(c.get("invalid_replies", 0)) for c in calls),
    }


def open_llm_agent(options: LLMOptions, view: Any, *, name: str = LLM_AGENT_NAME) -> LLMAgent:
    """An :class:`LLMAgent` with its own client for ``options``; ``close()`` releases the client.

    Raises
    ------
    LLMConfigError
        Settings that cannot build a client (no key outside replay, a cache mode without a directory).
    """
    client = StructuredLLM(options.settings, cache_dir=options.cache_dir, cache_mode=options.cache_mode)
    agent = LLMAgent(client, view, name=name)
    agent._owns_client = True
    return agent
