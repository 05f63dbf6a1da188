"""``solarchain-eval evaluate`` and ``solarchain-eval run`` (the main job)."""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from pathlib import Path

import typer

from ..agents.adapters import AgentError
from ..agents.registry import known_policies, parse_agents
from ..agents.sb3 import parse_models
from ..agents.specs import LLM_AGENT, parse_agent_args, parse_agent_list, parse_vecnormalize
from ..config import BenchmarkConfig, load_config
from ..evaluation.agent_setup import check_agents
from ..evaluation.run_spec import EvaluationSpec
from ..evaluation.rundir import RunDirError, check_target
from ..evaluation.runner import run_evaluation
from ..evaluation.settings import SETTINGS
from ..evaluation.settings_file import load_settings
from ..governance.request import GovernanceRequest
from ..protocol import PAPER_EPISODES, PAPER_SEEDS
from ..tasks.registry import DEFAULT_TASK, get_task
from ..tasks.suites import get_suite, suite_names
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
    register_user_error,
    reports_errors,
    result_columns,
    results_table,
    say,
    show_files,
)
from .progress import count_progress
from .suite import evaluate_suite

register_user_error(RunDirError, AgentError)
OVERWRITE = typer.Option(
    False,
    "--overwrite",
    help="Replace an existing run directory as a whole (its old files are removed, never mixed in).",
)

# The user-agent options of every command that names policies (evaluate, paper, governance).
AGENT_ARG = typer.Option(
    None,
    "--agent-arg",
    metavar="[NAME.]KEY=VALUE",
    help="An option for agents built from a class or factory (repeatable); VALUE is read as JSON when it is "
    "JSON. NAME. limits it to one agent.",
)
VECNORMALIZE = typer.Option(
    None,
    "--vecnormalize",
    metavar="[NAME=]PATH",
    help="VecNormalize statistics (VecNormalize.save) for an sb3: agent; NAME= picks the agent when there are several.",
)
# The settings file of every command that names settings (evaluate, paper): docs/settings.md.
SETTINGS_FILE = typer.Option(
    None,
    "--settings-file",
    help="YAML file declaring settings of your own (reward switch, governance, config overrides, the settings "
    "the report compares them with); see docs/settings.md.",
)
#: The --policies help of every command that takes agent specs (its default is the command's own).
USER_AGENTS_HELP = (
    "package.module:attr, path/to/file.py:attr, an installed plugin's name, NAME=sb3:ALGO:PATH.zip or "
    "NAME=http://HOST:PORT/PATH; NAME=spec names the row. See docs/evaluate_your_agent.md."
)

# An evaluate option, not a GovernanceRequest field: it schedules this command's episodes (paper and
# bench-llm run theirs in order), so it lives here, shown in the governance options' help panel.
ISOLATE = typer.Option(
    False,
    "--isolate",
    help="Run each user agent (module:attr, file.py:attr, plugin, sb3:) in a process of its own that receives "
    "only the observation, step info and public context; its rows are labelled isolated. "
    "See docs/evaluate_your_agent.md#isolated-agents.",
)
LLM_CONCURRENCY = typer.Option(
    1,
    "--llm-concurrency",
    min=1,
    help="Episodes in flight (threads) while waiting for the model, for servers that answer requests in parallel "
    "(vLLM, OpenAI, llama-server -np N); needs --agentic planner_auditor. The files are the same as with 1 when "
    "replies are deterministic (temperature 0 and a seed, or a replayed cache). With --llm-backend local the server "
    "accepts N requests without interrupting one (it answers them one at a time).",
    rich_help_panel=agentic_cli.PANEL,
)

_SEEDS = ",".join(str(s) for s in PAPER_SEEDS)


class StepFormat(StrEnum):
    csv = "csv"
    parquet = "parquet"


STEP_FORMAT = typer.Option(
    StepFormat.csv,
    "--step-format",
    help="The per-step tables as CSV (actions.csv, city_hour_policy.csv) or Parquet (actions.parquet, "
    "city_hour_policy.parquet: about a tenth of the size, for large evaluations). report, verify and leaderboard "
    "read both.",
)


def _default_run_dir(config: BenchmarkConfig, label: str) -> Path:
    return Path(config.output_dir) / f"{datetime.now().strftime('%Y%m%d-%H%M%S')}_{label}"


def _evaluate(spec: EvaluationSpec, out: Path, title: str, overwrite: bool, step_format: str = "csv") -> None:
    total = len(spec.policies) * len(spec.run_seeds) * spec.episodes
    with count_progress("evaluating", total) as advance:
        # Episodes are not kept once written: memory stays flat however many there are.
        outcome = run_evaluation(
            spec,
            out,
            on_episode=lambda _r: advance(1),
            command=invoked_command(),
            overwrite=overwrite,
            keep_results=False,
            step_format=step_format,
        )
    summary = outcome.summary
    console.print(results_table(summary, title, access=outcome.access, columns=result_columns(spec.task)))
    if spec.agentic is not None:
        console.print(agentic_cli.agentic_table(summary, f"Planner/Auditor ({spec.agentic.label()})"))
    show_files(outcome.files, f"wrote {outcome.episodes} episodes in {outcome.wall_s:.1f} s to {out}")
    say(f"protocol {outcome.protocol_id} (equal ids: comparable results; see run_metadata.json 'protocol')", err=False)


@app.command("evaluate")
@reports_errors
@agentic_cli.governance_options()
def evaluate(
    data: Path | None = typer.Option(
        None, "--data", help="Dataset directory (default: the config's data_dir, else the embedded default dataset)."
    ),
    policies: str | None = typer.Option(
        None,
        help=f"Comma-separated agents: built-in ({', '.join(known_policies())}, {LLM_AGENT}), {USER_AGENTS_HELP} "
        "Default: the config's evaluation.policies (static,random,myopic).",
    ),
    agent_arg: list[str] | None = AGENT_ARG,
    vecnormalize: list[str] | None = VECNORMALIZE,
    seeds: str = typer.Option(_SEEDS, help="Comma-separated run seeds; episode e of seed s is reset with s + e."),
    episodes: int | None = typer.Option(
        None, min=1, help=f"Episodes per run seed (default: the config's evaluation.episodes, {PAPER_EPISODES})."
    ),
    out: Path | None = typer.Option(None, "--out", help="Run directory (default: <output_dir>/<time>_evaluate)."),
    no_physics_penalty: bool = typer.Option(
        False, "--no-physics-penalty", help="The ablation: drop λp (V + A) from the reward; V and A are still recorded."
    ),
    setting: str | None = typer.Option(
        None,
        "--setting",
        help=f"A registered setting ({', '.join(SETTINGS)}, or one of --settings-file or a plugin). Default: main; "
        "no_physics with --no-physics-penalty; llm / llm_no_physics with --agentic planner_auditor.",
    ),
    settings_file: Path | None = SETTINGS_FILE,
    config: Path | None = typer.Option(None, "--config", help="YAML config in the paper's layout."),
    models: list[str] | None = typer.Option(
        None,
        "--models",
        metavar="DIR|NAME=PATH",
        help="Trained models: a directory, or NAME=PATH per learned policy (repeatable); "
        "SB3 model.zip or JAX jax_model.msgpack (train --backend jax).",
    ),
    governance: GovernanceRequest = GOVERNANCE,
    llm_concurrency: int = LLM_CONCURRENCY,
    overwrite: bool = OVERWRITE,
    isolate: bool = ISOLATE,
    step_format: StepFormat = STEP_FORMAT,
    task: str = TASK,
    suite: str | None = typer.Option(
        None,
        "--suite",
        metavar="NAME",
        help=f"Evaluate over every entry of a suite ({', '.join(suite_names())}): one run per entry under --out, "
        "with the suite's reference baselines, normalised scores and aggregates. See docs/suites.md.",
    ),
) -> None:
    """Evaluate policies over run seeds × episodes.

    Writes metrics.csv (one row per episode), actions.csv (one row per step), city_hour_policy.csv
    (one row per step and city), summary.json and run_metadata.json to the run directory, each
    file atomically. Episode e of run seed s is reset with seed s + e (the paper's protocol).

    With --agentic planner_auditor every policy runs behind the Planner/Auditor layer
    (rule planner and rule auditor by default; --planner llm / --auditor llm
    call an OpenAI-compatible endpoint, recordable and replayable with --llm-cache),
    and the run also writes agentic_logs.jsonl and governance_diagnostics.csv (see --no-diagnostics).

    With --task NAME another installed market is evaluated: its environment, its metrics (the
    metrics.csv columns) and its baselines (the default policies); --config is the solar market's.

    With --suite NAME every entry of the suite (a task on one dataset of one split) is evaluated
    into a run directory of its own under --out, beside suite_scores.csv, performance_profile.png
    and suite_metadata.json (written last).
    """
    chosen = get_suite(suite) if suite is not None else None  # an unknown name: one line, nothing written
    if chosen is not None and (data is not None or task != DEFAULT_TASK):
        raise CliError(f"--suite {suite} names its tasks and datasets; give neither --data nor --task")
    market = get_task(task)  # an unknown name: one line listing the installed tasks
    if config is not None and task != DEFAULT_TASK:
        raise CliError(f"--config is the solar market's configuration; task {task!r} takes its own defaults")
    cfg = load_config(config) if config else BenchmarkConfig()
    if settings_file is not None:
        load_settings(settings_file)
    if out is not None:
        check_target(out, overwrite=overwrite)  # before any work (checked again under the lock)
    try:
        if task == DEFAULT_TASK:
            specs = parse_agents(policies if policies is not None else ",".join(cfg.evaluation.policies))
        else:  # the task's baselines are its built-in names (the solar market's are refused by the runner)
            names = tuple(market.baselines())
            specs = parse_agent_list(policies if policies is not None else ",".join(names), (*names, *known_policies()))
        named = [s.name for s in specs if s.name is not None]
        agent_args = parse_agent_args(agent_arg or [], named)
    except ValueError as error:
        raise cli_error(error) from None
    options = agentic_cli.resolve(governance)
    llm_agent = any(s.kind == "llm" for s in specs)
    if llm_concurrency > 1 and options is None and not llm_agent:
        raise CliError("--llm-concurrency needs --agentic planner_auditor or the llm-agent")
    spec_options = dict(
        run_seeds=parse_seeds(seeds),
        episodes=episodes if episodes is not None else cfg.evaluation.episodes,
        no_physics_penalty=no_physics_penalty or None,  # unset: the setting's reward
        config=cfg if task == DEFAULT_TASK else None,  # None: the task's default configuration
        models=parse_models(models or []),
        agentic=options,
        setting=setting,
        concurrency=llm_concurrency,
        agent_args=agent_args,
        vecnormalize=parse_vecnormalize(vecnormalize or [], named),
        # llm-agent: the model endpoint of the same --llm-* options as an LLM planner's
        llm=agentic_cli.llm_agent_options(governance) if llm_agent else None,
        isolate=isolate,
    )
    if chosen is not None:
        with agentic_cli.serving(governance, options, parallel=llm_concurrency, needs_llm=llm_agent):
            evaluate_suite(
                chosen,
                lambda entry, data_dir, policies: EvaluationSpec(
                    policies=policies,
                    data_dir=data_dir,
                    task=entry.task,
                    # --config is the solar market's: another task's entry takes its own defaults
                    # the entry's own fields (a within-month split's start days) on top
                    **{**spec_options, "config": entry.configure(cfg if entry.task == DEFAULT_TASK else None)},
                ),
                [s.text for s in specs],
                out or _default_run_dir(cfg, f"suite-{chosen.name}"),
                overwrite=overwrite,
                step_format=step_format.value,
            )
        return
    spec = EvaluationSpec(policies=[s.text for s in specs], data_dir=data, task=task, **spec_options)
    try:
        check_agents(spec)  # unknown names, imports, models, names used twice, action shapes: before any work
    except (ValueError, FileNotFoundError) as error:
        raise cli_error(error) from None
    label = "evaluate" if options is None and setting is None else f"evaluate-{spec.setting}"
    # --llm-backend local: started here, always stopped; one server slot per episode in flight
    with agentic_cli.serving(governance, options, parallel=llm_concurrency, needs_llm=llm_agent):
        _evaluate(spec, out or _default_run_dir(cfg, label), "evaluation", overwrite, step_format.value)


@app.command("run")
@reports_errors
def run(
    out: Path | None = typer.Option(None, "--out", help="Run directory (default: outputs/runs/<time>_baselines)."),
    episodes: int = typer.Option(PAPER_EPISODES, min=1, help="Episodes per run seed."),
    seeds: str = typer.Option(_SEEDS, help="Comma-separated run seeds."),
    overwrite: bool = OVERWRITE,
    task: str = TASK,
) -> None:
    """The main job: evaluate the baselines on the embedded default dataset.

    The default dataset is the paper's published dataset: built offline once from the paper's
    Open-Meteo weather shipped with the package, checked against the published sha256s, into
    the user cache directory and reused afterwards. Evaluates Static, Random and Myopic with
    the paper's protocol and prints the results table, the files written, and the main table
    beside the paper's published values. With --task NAME, another installed market's baselines
    on its default data (no paper comparison).
    """
    from ..common.atomic_files import read_csv_exact
    from ..evaluation.records import METRICS_FILE
    from ..report.against_paper.tables import main_table_against_paper
    from .common import paper_results_table

    market = get_task(task)
    cfg = BenchmarkConfig()
    out = out or _default_run_dir(cfg, "baselines")
    check_target(out, overwrite=overwrite)
    if task != DEFAULT_TASK:
        other = EvaluationSpec(
            policies=list(market.baselines()), run_seeds=parse_seeds(seeds), episodes=episodes, task=task
        )
        _evaluate(other, out, f"baselines of task {task}", overwrite)
        return
    dataset = market.data_dir(None, cfg)  # the default dataset; logs a one-line notice when it builds
    spec = EvaluationSpec(
        policies=["static", "random", "myopic"],
        run_seeds=parse_seeds(seeds),
        episodes=episodes,
        data_dir=dataset,
        config=cfg,
    )
    say(
        f"dataset: {dataset} (the paper's published dataset, rebuilt from the packaged weather; sha256s checked)",
        err=False,
    )
    _evaluate(spec, out, "baselines on the paper's dataset", overwrite)
    comparison = main_table_against_paper(read_csv_exact(out / METRICS_FILE))
    table, line = paper_results_table(comparison, "against the paper's main table (its published values)")
    console.print(table)
    protocol = (
        ""
        if (list(spec.run_seeds), spec.episodes) == (list(PAPER_SEEDS), PAPER_EPISODES)
        else (f" (the paper's protocol is {len(PAPER_SEEDS)} seeds × {PAPER_EPISODES} episodes)")
    )
    say(line + protocol, err=False)
