"""``solarchain-eval paper``: the full experiment grid (train -> evaluate -> combined files)."""

from __future__ import annotations

import dataclasses
import json
from enum import StrEnum
from pathlib import Path
from typing import Any

import typer
from rich.text import Text

from ..agents.checkpoints import OPT_IN_ALGOS
from ..agents.registry import parse_policy_list
from ..agents.specs import parse_agent_args, parse_vecnormalize
from ..config import BenchmarkConfig, load_config
from ..evaluation.records import SUMMARY_FILE
from ..evaluation.settings import KNOWN_SETTINGS
from ..evaluation.settings_file import load_settings
from ..experiments.grid import GridSpec, Unit, plan_units
from ..experiments.layout import combined_dir
from ..experiments.paper import GridError, run_paper
from ..experiments.units import UnitProgress, UnitResult
from ..experiments.user_agents import PolicyChoice, resolve_agents, split_policies
from ..governance.request import GovernanceRequest
from ..protocol import EPISODE_SEED_RULE_LINES, EPISODE_SEED_RULES, PAPER_EPISODES, PAPER_SEEDS, PAPER_TIMESTEPS
from ..tasks.governance_view import GovernedTask
from ..tasks.registry import DEFAULT_TASK, get_task
from ..training.jax_progress import DEFAULT_CHUNK_STEPS
from ..training.lagrangian import DEFAULT_COST_LIMIT, DEFAULT_MULTIPLIER_LR, LagrangianSettings
from . import agentic as agentic_cli
from . import app
from .agentic import GOVERNANCE
from .common import (
    CliError,
    cli_error,
    console,
    err_console,
    invoked_command,
    parse_seeds,
    refuse_file_out,
    register_user_error,
    reports_errors,
    result_columns,
    results_table,
)
from .evaluate import AGENT_ARG, ISOLATE, SETTINGS_FILE, USER_AGENTS_HELP, VECNORMALIZE
from .progress import TrainingProgress

register_user_error(GridError)


class Preset(StrEnum):
    paper = "paper"
    smoke = "smoke"


#: The --episode-seeds choices: the rules of protocol.py.
EpisodeSeeds = StrEnum("EpisodeSeeds", {name: name for name in EPISODE_SEED_RULES})
_EPISODE_SEEDS_HELP = " ".join(f"{name}: {line}" for name, line in EPISODE_SEED_RULE_LINES.items())


def _settings(text: str | None, task: str = DEFAULT_TASK) -> tuple[str, ...]:
    if not text:
        if governance_of(task):
            return tuple(KNOWN_SETTINGS)
        # the Planner/Auditor layer needs the market's governance view: without one, the ungoverned settings
        ungoverned = tuple(name for name, setting in KNOWN_SETTINGS.items() if not setting.agentic)
        typer.echo(f"task {task!r} supplies no governance view: settings {', '.join(ungoverned)} only")
        return ungoverned
    names = tuple(part.strip() for part in text.split(",") if part.strip())
    unknown = [n for n in names if n not in KNOWN_SETTINGS]
    if unknown:
        raise CliError(f"unknown setting(s) {', '.join(unknown)} (available: {', '.join(KNOWN_SETTINGS)})")
    return names


def governance_of(task: str) -> bool:
    """Whether the Planner/Auditor layer can govern ``task`` (it supplies a governance view)."""
    return isinstance(get_task(task), GovernedTask)


def _choice(text: str | None) -> PolicyChoice:
    """``--policies`` split into built-in policies and the specs of user agents."""
    choice = split_policies(text.split(",")) if text else PolicyChoice((), ())
    if text and not choice.builtins and not choice.agents:
        raise ValueError("--policies: no policies given")
    return choice


def _policies(text: str | None, extra: str | None, settings: tuple[str, ...]) -> tuple[str, ...] | None:
    """The built-in policies of ``--policies`` plus ``--extra-policies`` (None: every non-opt-in
    policy of the settings; user agents are :func:`_choice`'s)."""
    extras = parse_policy_list(extra) if extra else []
    unknown = [p for p in extras if p not in OPT_IN_ALGOS]
    if unknown:
        raise ValueError(f"--extra-policies: {', '.join(unknown)} is not an opt-in policy ({', '.join(OPT_IN_ALGOS)})")
    if not text and not extras:
        return None
    defaults = dict.fromkeys(p for s in settings for p in KNOWN_SETTINGS[s].policies if p not in OPT_IN_ALGOS)
    base = list(_choice(text).builtins) if text else list(defaults)
    return tuple(dict.fromkeys([*base, *extras]))


def _run_with_progress(spec: GridSpec, out: Path, **run_options: Any):
    """``run_paper`` with progress: a line per finished unit and, for JAX train units, their
    steps, recent return, steps/s and ETA after every chunk (a live display on a terminal, with
    a bar over the units; plain lines otherwise)."""
    from ..experiments.ray_executor import RayUnavailableError

    with TrainingProgress(units=len(plan_units(spec))) as display:

        def on_plan(units: list[Unit], already: list[str]) -> None:
            if already:
                err_console.print(f"{len(already)} of {len(units)} units already done: skipped")
                display.advance_units(len(already))

        def on_start(unit: Unit) -> None:
            if unit.kind == "train" and unit.backend == "jax":
                display.start(unit.name, spec.timesteps)

        def on_progress(news: UnitProgress) -> None:
            if news.progress is not None:
                display.update(news.unit, news.progress)
            if news.note is not None:
                display.note(news.unit, news.note)

        def on_result(result: UnitResult) -> None:
            display.finish(result.unit)
            display.advance_units(1)
            if result.ok:
                cpu = f", {result.cpu_s:.1f} CPU s" if result.cpu_s is not None else ""
                err_console.print(
                    Text.assemble(("done", "green"), f" {result.unit} ({result.wall_s:.1f} s{cpu})"), soft_wrap=True
                )
            else:
                err_console.print(
                    Text.assemble(("FAILED", "bold red"), f" {result.unit}: {result.error}\n  log: {result.log}"),
                    soft_wrap=True,
                )

        try:
            return run_paper(
                spec,
                out,
                on_plan=on_plan,
                on_start=on_start,
                on_result=on_result,
                on_progress=on_progress,
                command=invoked_command(),
                **run_options,
            )
        except RayUnavailableError as error:
            raise cli_error(error) from None


def _show_outcome(outcome, task: str = DEFAULT_TASK) -> None:
    """Each combined setting's results table, the root's status, and the failed units (exit 1)."""
    report = outcome.report
    for setting in outcome.combined:
        summary = json.loads((combined_dir(outcome.root, setting) / SUMMARY_FILE).read_text(encoding="utf-8"))
        console.print(results_table(summary, f"setting {setting}", columns=result_columns(task)))
        protocol = outcome.protocols.get(setting, {}).get("protocol_id")
        if protocol:
            console.print(f"setting {setting}: protocol {protocol}", soft_wrap=True)
    cpu_s = sum(r.cpu_s for r in report.finished if r.cpu_s is not None)
    console.print(
        f"paper root: {outcome.root} ({'complete' if outcome.complete else 'INCOMPLETE'}, {outcome.wall_s:.1f} s; "
        f"units run now: {len(report.finished)}, {cpu_s:.1f} CPU s)",
        soft_wrap=True,
    )
    if report.failed:
        lines = [f"  {r.unit}: {r.error} (log: {r.log})" for r in report.failed]
        extra = ""
        if report.stopped:
            extra = (
                f"\nstopped; {len(report.interrupted)} unit(s) in flight were interrupted. "
                f"Re-run to resume, or add --keep-going."
            )
        elif report.blocked:
            extra = f"\n{len(report.blocked)} unit(s) not run because a unit they need failed."
        err_console.print(
            Text.assemble((f"{len(report.failed)} unit(s) failed:", "bold red"), "\n" + "\n".join(lines) + extra),
            soft_wrap=True,
        )
        raise typer.Exit(1)


@app.command("paper")
@reports_errors
@agentic_cli.governance_options(fixed={"agentic": "planner_auditor"})
def paper(
    out: Path = typer.Option(..., "--out", help="The paper root (created; re-run the same command to resume)."),
    data: Path | None = typer.Option(
        None,
        "--data",
        help="Dataset directory (default: the embedded default dataset, which is the paper's published one).",
    ),
    preset: Preset = typer.Option(
        Preset.paper,
        "--preset",
        help=f"paper: {PAPER_TIMESTEPS:,} steps, {PAPER_EPISODES} episodes, seeds {PAPER_SEEDS[0]}-{PAPER_SEEDS[-1] % 100}. "
        "smoke: tiny budgets.",
    ),
    timesteps: int | None = typer.Option(
        None, "--timesteps", min=1, help="Training steps per model (overrides the preset)."
    ),
    episodes: int | None = typer.Option(
        None, "--episodes", min=1, help="Evaluation episodes per run seed (overrides the preset)."
    ),
    seeds: str | None = typer.Option(None, "--seeds", help="Comma-separated run seeds (overrides the preset)."),
    settings: str | None = typer.Option(
        None, "--settings", help="Comma-separated settings (default: every registered one: main, no_physics, ...)."
    ),
    settings_file: Path | None = SETTINGS_FILE,
    policies: str | None = typer.Option(
        None,
        "--policies",
        help="Comma-separated subset of the policies to run (default: all; train units follow), and agents of "
        f"your own, evaluated in every setting: {USER_AGENTS_HELP}",
    ),
    agent_arg: list[str] | None = AGENT_ARG,
    vecnormalize: list[str] | None = VECNORMALIZE,
    isolate: bool = ISOLATE,
    extra_policies: str | None = typer.Option(
        None,
        "--extra-policies",
        help=f"Comma-separated opt-in policies added to the run ({', '.join(OPT_IN_ALGOS)}: PPO-Lagrangian, "
        "evaluated in main and no_physics).",
    ),
    cost_limit: float = typer.Option(
        DEFAULT_COST_LIMIT, "--cost-limit", min=0.0, help="ppo-lag: the episode-cost limit D."
    ),
    multiplier_lr: float = typer.Option(
        DEFAULT_MULTIPLIER_LR, "--multiplier-lr", min=0.0, help="ppo-lag: the dual-ascent step size."
    ),
    workers: int = typer.Option(1, "--workers", min=1, help="Local worker processes (one torch thread each)."),
    backend: str = typer.Option(
        "sb3",
        "--backend",
        help="Train units' backend: sb3 (Stable-Baselines3, the reference) or jax (rejax; needs the jax extra; "
        "one unit per seed group, trained in checkpointed chunks; docs/jax.md).",
    ),
    ray_address: str | None = typer.Option(
        None,
        "--ray-address",
        help="Run units as Ray tasks: auto, ray://host:port, or local (needs the ray extra: pip install -e '.[ray]').",
    ),
    episode_seeds: EpisodeSeeds = typer.Option(
        EpisodeSeeds.paper,
        "--episode-seeds",
        help=_EPISODE_SEEDS_HELP,
    ),
    keep_going: bool = typer.Option(False, "--keep-going", help="Record failing units and carry on with the others."),
    checkpoint_every: int | None = typer.Option(
        None,
        "--checkpoint-every",
        min=0,
        help="Training steps between checkpoints (default 25,000; 0: none; SB3 only: JAX checkpoints every chunk).",
    ),
    chunk_steps: int | None = typer.Option(
        None,
        "--chunk-steps",
        min=1,
        help="JAX backend: env steps per compiled chunk, after which progress is shown and the state "
        f"checkpointed (default: {', '.join(f'{a.upper()} {n:,}' for a, n in DEFAULT_CHUNK_STEPS.items())}).",
    ),
    config: Path | None = typer.Option(None, "--config", help="YAML config in the paper's layout."),
    write_report: bool = typer.Option(
        True, "--report/--no-report", help="Write ROOT/report (tables, figures, index.html) after a complete grid."
    ),
    governance: GovernanceRequest = GOVERNANCE,
    task: str = typer.Option(
        DEFAULT_TASK, "--task", help="The task every unit trains and evaluates on (default: the solar market)."
    ),
) -> None:
    """The paper's experiment matrix: train, evaluate, combine, report.

    The paper preset is 18 models and 54 evaluation units in 4 settings.

    Trains PPO, SAC and DQN per seed with and without the physics penalty; evaluates static,
    random, myopic, ppo, sac and dqn per seed in the settings main and no_physics, and the learned
    policies behind the Planner/Auditor layer in llm and llm_no_physics (rule planner and auditor
    unless --planner/--auditor say otherwise); writes ROOT/combined/<setting>/ files,
    ROOT/paper_metadata.json and, after a complete grid, the report in ROOT/report.

    --policies also takes your own agents (package.module:attr, path/to/file.py:attr, plugins,
    NAME=sb3:ALGO:PATH.zip, NAME=http://...; with --agent-arg, --vecnormalize and --isolate as in
    evaluate): each is evaluated, not trained, in every setting (behind the Planner/Auditor layer in
    the agentic ones), in units named by the agent.

    --extra-policies ppo-lag adds PPO-Lagrangian (train --algo ppo-lag) in main and no_physics,
    with --cost-limit and --multiplier-lr.

    Every unit (a trained model, or one policy × setting × seed evaluation) is a directory under
    ROOT/units with a DONE marker written last: re-running the same command skips finished units
    and redoes the ones that were in flight (training resumes from its last checkpoint; with
    --backend jax, from its last chunk).
    """
    refuse_file_out(out)
    cfg = load_config(config) if config else BenchmarkConfig()
    options = agentic_cli.resolve(governance)
    if settings_file is not None:
        load_settings(settings_file)
    chosen_settings = _settings(settings, get_task(task).name)
    try:
        builtins, choice = _policies(policies, extra_policies, chosen_settings), _choice(policies)
        named = [s.name for s in choice.agents if s.name is not None]
        agent_args = parse_agent_args(agent_arg or [], named)
        stats = parse_vecnormalize(vecnormalize or [], named)
        spec = GridSpec.from_preset(
            preset.value,
            timesteps=timesteps,
            episodes=episodes,
            seeds=tuple(parse_seeds(seeds)) if seeds else None,
            settings=chosen_settings,
            policies=builtins,
            episode_seed_protocol=episode_seeds.value,
            data_dir=data,
            config=cfg,
            checkpoint_every=checkpoint_every,
            agentic=options,
            backend=backend,
            lagrangian=LagrangianSettings(cost_limit, multiplier_lr),
            agent_args=agent_args,
            vecnormalize=stats,
            isolate=isolate,
            chunk_steps=chunk_steps,
            task=get_task(task).name,  # an unknown task is a one-line error here
        )
        if chunk_steps is not None and spec.backend != "jax":
            raise CliError("--chunk-steps applies to --backend jax (SB3 checkpoints every --checkpoint-every steps)")
        # User agents are named by building them once, which also checks imports, models and
        # action shapes on the grid's dataset before any unit runs.
        agents = resolve_agents(
            choice.agents,
            config=cfg,
            agent_args=agent_args,
            vecnormalize=stats,
            data_dirs=[data],
            run_seed=spec.seeds[0],
            builtins=builtins or (),
            isolate=isolate,
        )
        spec = dataclasses.replace(spec, agents=agents)
        spec.validate()
    except (ValueError, FileNotFoundError) as error:
        raise cli_error(error) from None
    where = f"Ray ({ray_address})" if ray_address else f"{workers} worker(s)"
    mine = f", your agents {', '.join(name for name, _ in spec.agents)}" if spec.agents else ""
    err_console.print(
        f"grid: {spec.timesteps:,} training steps, {spec.episodes} episodes × {len(spec.seeds)} seed(s), "
        f"settings {', '.join(spec.settings)}{mine}, {spec.backend} backend, on {where} -> {out}",
        soft_wrap=True,
    )
    with agentic_cli.serving(governance, options):
        outcome = _run_with_progress(spec, out, workers=workers, ray_address=ray_address, keep_going=keep_going)
    _show_outcome(outcome, spec.task)
    if outcome.complete and write_report:
        from ..report import build_report

        written = build_report(outcome.root)
        console.print(f"report: {written.out_dir / 'index.html'}", soft_wrap=True)
