"""``solarchain-eval governance``: the governance leaderboard (docs/governance.md#leaderboard)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pandas as pd
import typer
from rich.table import Table

from ..agents.registry import known_policies, parse_agents
from ..agents.request import AgentContext, agent_requests
from ..agents.sb3 import parse_models
from ..agents.specs import parse_agent_args, parse_agent_list, parse_vecnormalize
from ..config import load_config
from ..evaluation.rundir import RunDirWriter, check_target
from ..evaluation.settings import AGENTIC_SETTINGS
from ..experiments.governance import (
    GOVERNANCE_METADATA_FILE,
    Combination,
    CombinationRun,
    GovernanceSpec,
    run_governance,
)
from ..experiments.user_agents import refuse_llm_agent
from ..governance.calibrated import DEFAULT_TARGET_AUDIT_RATE
from ..governance.controls import DEFAULT_ORACLE_REWARD_LOSS, TRIGGER_SETS, SchedulerControls
from ..governance.counterfactual import DEFAULT_UNSAFE_THRESHOLD
from ..governance.errors import GovernanceConfigError
from ..governance.request import GovernanceRequest
from ..protocol import PAPER_EPISODES, PAPER_SEEDS
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import DEFAULT_TASK, get_task
from . import agentic as agentic_cli
from . import app
from .agentic import GOVERNANCE
from .common import (
    TASK,
    CliError,
    cli_error,
    console,
    invoked_command,
    parse_seeds,
    progress_bar,
    reports_errors,
    say,
    show_files,
)
from .evaluate import AGENT_ARG, ISOLATE, OVERWRITE, USER_AGENTS_HELP, VECNORMALIZE

METADATA = GOVERNANCE_METADATA_FILE  # the name this module always had
#: The Planner/Auditor options this command offers as they are: the LLM endpoint and its cache
#: (planners, auditors and the model come from --planner/--auditors; diagnostics are always on).
LLM_FIELDS = (
    "llm_backend",
    "llm_api",
    "llm_base_url",
    "llm_temperature",
    "llm_timeout",
    "llm_max_retries",
    "llm_max_output_tokens",
    "llm_threads",
    "llm_decoding",
    "llm_cache",
    "llm_cache_mode",
)


def _split(text: str, what: str) -> list[str]:
    items = list(dict.fromkeys(part.strip() for part in text.split(",") if part.strip()))
    if not items:
        raise CliError(f"no {what} given")
    return items


def _kind(name: str) -> tuple[str, str | None]:
    """``llm:MODEL`` -> ("llm", MODEL); anything else -> (name, None)."""
    if name.startswith("llm:"):
        model = name[4:].strip()
        if not model:
            raise CliError(f"'{name}': give the model after 'llm:'")
        return "llm", model
    return name, None


def _combination(
    planner: str, auditor: str, governance: GovernanceRequest, extra: dict[str, Any]
) -> tuple[Combination, GovernanceRequest]:
    """The combination of ``planner`` and ``auditor`` (``llm:MODEL`` names allowed) and the request behind it."""
    planner_kind, planner_model = _kind(planner)
    auditor_kind, auditor_model = _kind(auditor)
    if planner_model and auditor_model and planner_model != auditor_model:
        raise CliError(f"planner {planner} and auditor {auditor} name different models; one run uses one model")
    request = dataclasses.replace(
        governance,
        agentic="planner_auditor",
        planner=planner_kind,
        auditor=auditor_kind,
        llm_model=planner_model or auditor_model or governance.llm_model,
    )
    options = agentic_cli.resolve(request)
    assert options is not None
    try:
        options = dataclasses.replace(options, **extra)
    except GovernanceConfigError as error:
        raise cli_error(error) from None
    return Combination(planner, auditor, options), request


def _leaderboard_table(frame: pd.DataFrame, title: str) -> Table:
    table = Table(title=title, title_justify="left")
    columns = (
        ("#", "rank", "{:.0f}"),
        ("planner", "planner", "{}"),
        ("auditor", "auditor", "{}"),
        ("setting", "setting", "{}"),
        ("audit rate", "audit_rate", "{:.3f}"),
        ("precision", "precision", "{:.3f}"),
        ("recall", "recall", "{:.3f}"),
        ("Δcost/step", "delta_cost_per_step", "{:+.5f}"),
        ("Δreward/step", "delta_reward_per_step", "{:+.5f}"),
        ("Δart.liq/step", "delta_artificial_liquidity_per_step", "{:+.6f}"),
        ("Δcost vs none", "total_delta_cost_per_step", "{:+.5f}"),
        ("calls", "llm_calls", "{:.0f}"),
        ("tokens", "llm_tokens", "{:.0f}"),
        ("latency s", "llm_mean_latency_s", "{:.3f}"),
    )
    for header, _, _ in columns:
        table.add_column(header, justify="left" if header in ("planner", "auditor", "setting") else "right")
    for row in frame.to_dict("records"):
        table.add_row(*(fmt.format(row[key]) for _, key, fmt in columns))
    return table


@app.command("governance")
@reports_errors
@agentic_cli.governance_options(only=LLM_FIELDS)
def governance(
    data: Path | None = typer.Option(
        None, "--data", help="Dataset directory (default: the config's data_dir, else the embedded default dataset)."
    ),
    auditors: str = typer.Option(
        "rule,approve-only,random,oracle",
        "--auditors",
        help="Comma-separated auditors: rule, approve-only, always-audit, random (seeded; as many audits per "
        "episode as the rule auditor of the same planner), oracle (least cost at bounded reward loss), llm:MODEL "
        "(an OpenAI-compatible endpoint, see the LLM options).",
    ),
    planner: str = typer.Option(
        "rule", "--planner", help="Comma-separated planners: rule, calibrated-rule, default, llm:MODEL."
    ),
    policies: str | None = typer.Option(
        None,
        help=f"Comma-separated policies ({', '.join(known_policies())}) or {USER_AGENTS_HELP} "
        "Default: static,random,myopic (with --task, the task's baselines).",
    ),
    agent_arg: list[str] | None = AGENT_ARG,
    vecnormalize: list[str] | None = VECNORMALIZE,
    isolate: bool = ISOLATE,
    models: list[str] | None = typer.Option(
        None, "--models", metavar="DIR|NAME=PATH", help="Trained models: a directory, or NAME=PATH (repeatable)."
    ),
    seeds: str = typer.Option(",".join(str(s) for s in PAPER_SEEDS), help="Comma-separated run seeds."),
    episodes: int = typer.Option(PAPER_EPISODES, min=1, help="Episodes per run seed."),
    settings: str = typer.Option("llm", help=f"Comma-separated agentic settings ({', '.join(AGENTIC_SETTINGS)})."),
    unsafe_threshold: float = typer.Option(
        DEFAULT_UNSAFE_THRESHOLD, min=0.0, help="A step is unsafe when its proposal's avoidable cost exceeds this."
    ),
    oracle_reward_loss: float = typer.Option(
        DEFAULT_ORACLE_REWARD_LOSS, min=0.0, help="The oracle's largest reward loss against ā per audited step."
    ),
    target_audit_rate: float = typer.Option(
        DEFAULT_TARGET_AUDIT_RATE, min=0.0, max=1.0, help="The calibrated-rule planner's target audit rate."
    ),
    triggers: str = typer.Option(
        "all",
        help=f"Comma-separated trigger ablations ({', '.join(TRIGGER_SETS)}): each one is a further planner variant, "
        "labelled PLANNER[TRIGGERS] (all: as planned).",
    ),
    max_audits: int | None = typer.Option(None, min=1, help="Override the plan's max audits per episode."),
    cooldown: int | None = typer.Option(None, min=0, help="Override the plan's cooldown (steps)."),
    random_seed: int = typer.Option(0, help="Seed of the random auditor's choice of steps."),
    resamples: int = typer.Option(2000, min=100, help="Bootstrap resamples per interval."),
    out: Path = typer.Option(..., "--out", help="Leaderboard directory (published as a whole)."),
    config: Path | None = typer.Option(None, "--config", help="YAML config in the paper's layout."),
    governance: GovernanceRequest = GOVERNANCE,
    overwrite: bool = OVERWRITE,
    task: str = TASK,
) -> None:
    """Score planners and auditors against counterfactual ground truth.

    Every planner × auditor combination governs the same policies over the same seeds and
    episodes, with counterfactual diagnostics on. Writes runs/<setting>/<planner>--<auditor>/ (each
    a full run directory with governance_diagnostics.csv), leaderboard.csv/.md ranked by Δcost per
    step (audit rate, precision, recall, Δcost, Δreward, Δartificial liquidity with cluster-bootstrap
    intervals over start days; LLM calls, tokens, latency), leaderboard_by_policy.csv/.md and
    figures/ (precision–recall per auditor; Δcost vs Δreward per revision). See docs/governance.md.

    --policies also takes your own agents (package.module:attr, path/to/file.py:attr, plugins,
    NAME=sb3:ALGO:PATH.zip, NAME=http://...; with --agent-arg, --vecnormalize and --isolate as in
    evaluate).

    With --task NAME another installed market is governed through its governance view: its
    environment, its baselines (the default policies) and its own diagnostics columns; the
    leaderboard's metadata records the task. --config is the solar market's.
    """
    market = get_task(task)  # an unknown name: one line listing the installed tasks
    governance_view_of(market)  # no governance view: one line, nothing written
    if config is not None and task != DEFAULT_TASK:
        raise CliError(f"--config is the solar market's configuration; task {task!r} takes its own defaults")
    cfg = load_config(config) if config else market.default_config()  # the solar market's: BenchmarkConfig()
    check_target(out, overwrite=overwrite)
    try:
        if task == DEFAULT_TASK:
            specs = parse_agents(policies if policies is not None else "static,random,myopic")
        else:  # the task's baselines are its built-in names (the solar market's are refused by the runner)
            names = tuple(market.baselines())
            specs = parse_agent_list(policies if policies is not None else ",".join(names), (*names, *known_policies()))
        named = [s.name for s in specs if s.name is not None]
        agent_args = parse_agent_args(agent_arg or [], named)
        stats = parse_vecnormalize(vecnormalize or [], named)
        refuse_llm_agent(specs)
    except ValueError as error:
        raise cli_error(error) from None
    chosen_settings = _split(settings, "settings")
    unknown = [s for s in chosen_settings if s not in AGENTIC_SETTINGS]
    if unknown:
        raise CliError(
            f"--settings: unknown setting(s) {', '.join(unknown)} (choose from {', '.join(AGENTIC_SETTINGS)})"
        )
    combinations = []
    llm_request: GovernanceRequest | None = None  # the request of the first combination that calls an LLM
    for trigger_set in _split(triggers, "trigger sets"):
        try:
            controls = SchedulerControls(triggers=trigger_set, max_audits=max_audits, cooldown_steps=cooldown)
        except GovernanceConfigError as error:
            raise cli_error(error) from None
        extra = {
            "controls": controls,
            "target_audit_rate": target_audit_rate,
            "oracle_reward_loss": oracle_reward_loss,
            "random_seed": random_seed,
        }
        for p in _split(planner, "planners"):
            for a in _split(auditors, "auditors"):
                combination, request = _combination(p, a, governance, extra)
                if llm_request is None and combination.options.uses_llm:
                    llm_request = request
                if trigger_set != "all":
                    combination = dataclasses.replace(combination, planner_label=f"{p}[{trigger_set}]")
                combinations.append(combination)
    spec = GovernanceSpec(
        policies=[s.text for s in specs],
        combinations=combinations,
        settings=chosen_settings,
        run_seeds=parse_seeds(seeds),
        episodes=episodes,
        data_dir=data,
        config=cfg,
        models=parse_models(models or []),
        agent_args=agent_args,
        vecnormalize=stats,
        isolate=isolate,
        unsafe_threshold=unsafe_threshold,
        task=task,
    )
    names = _check_agents(spec)
    total = len(combinations) * len(chosen_settings) * len(names) * len(spec.run_seeds) * episodes
    llm_options = next((c.options for c in combinations if c.options.uses_llm), None)
    with (
        RunDirWriter(out, overwrite=overwrite) as writer,
        agentic_cli.serving(llm_request or governance, llm_options),
    ):
        assert writer.staging is not None
        from ..report.governance.leaderboard import governance_leaderboard, write_governance_leaderboard

        made: dict[str, Any] = {}  # the board (printed below) and its files

        def leaderboard(runs: list[CombinationRun], root: Path) -> dict[str, Path]:
            made["board"] = governance_leaderboard(runs, threshold=unsafe_threshold, resamples=resamples)
            made["files"] = write_governance_leaderboard(made["board"], root)
            return made["files"]

        with progress_bar("governing", total) as advance:
            run_governance(
                spec,
                writer.staging,
                on_episode=lambda _r: advance(1),
                on_combination=lambda c, s: say(f"{s}: {c.planner_label} planner, {c.auditor_label} auditor"),
                command=invoked_command(),
                tables=leaderboard,
            )
        writer.publish()
    board, files = made["board"], made["files"]
    console.print(
        _leaderboard_table(
            board.ranked, f"Governance leaderboard ({', '.join(names)}; unsafe: avoidable cost > {unsafe_threshold:g})"
        )
    )
    show_files({name: out / name for name in [*files, METADATA]}, f"wrote the leaderboard to {out}")


def _check_agents(spec: GovernanceSpec) -> list[str]:
    """The policies' names; unknown policies, missing models, imports, names used twice and
    actions of the wrong shape fail before any work."""
    from ..evaluation.agent_setup import check_agent_requests

    try:
        requests = agent_requests(
            spec.policies,
            models=spec.models,
            agent_args=spec.agent_args,
            vecnormalize=spec.vecnormalize,
            isolate=spec.isolate,
            task=spec.task,
        )
        return check_agent_requests(
            requests, AgentContext(spec.config, spec.task), data_dir=spec.data_dir, run_seed=spec.run_seeds[0]
        )
    except (ValueError, FileNotFoundError) as error:
        raise cli_error(error) from None
