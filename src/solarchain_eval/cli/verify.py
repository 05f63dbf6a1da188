"""``solarchain-eval verify``: check a run's files, then re-run a sample of its episodes."""

from __future__ import annotations

from pathlib import Path

import typer

from ..agents.registry import known_policies
from ..agents.sb3 import parse_models
from ..agents.specs import parse_agent_args, parse_agent_spec
from ..evaluation.verify import DEFAULT_VERIFY_EPISODES, RunVerification, VerifyError, VerifyOptions, verify_run
from . import app
from .common import CliError, cli_error, register_user_error, reports_errors, say

register_user_error(VerifyError)


@app.command("verify")
@reports_errors
def verify(
    run: Path = typer.Argument(
        ...,
        metavar="RUN",
        help="A run directory (evaluate --out), a paper grid root or a suite root (evaluate --suite).",
    ),
    episodes: int = typer.Option(
        DEFAULT_VERIFY_EPISODES, "--episodes", min=1, help="Episodes re-run per policy, chosen at random."
    ),
    agents: list[str] | None = typer.Option(
        None,
        "--agent",
        metavar="AGENT",
        help="The code of one of the run's user agents (the grammar of evaluate --policies; repeatable), "
        "matched to the run's policies by name. User agents are never rebuilt from the run's own record.",
    ),
    agent_arg: list[str] | None = typer.Option(
        None,
        "--agent-arg",
        metavar="[NAME.]KEY=VALUE",
        help="An option for agents given with --agent (repeatable), as in evaluate.",
    ),
    llm_cache: Path | None = typer.Option(
        None, "--llm-cache", help="The record/replay cache the run's LLM calls are replayed from (replay mode)."
    ),
    seed: int | None = typer.Option(
        None, "--seed", help="Seed of the episode choice (default: derived from the run's run_id, so reproducible)."
    ),
    data_dir: Path | None = typer.Option(
        None,
        "--data",
        help="The run's dataset, when the recorded data_dir moved or changed; its CSVs must have the recorded sha256.",
    ),
    models: list[str] | None = typer.Option(
        None,
        "--models",
        metavar="DIR|NAME=PATH",
        help="Trained models of the run's learned policies, as in evaluate (repeatable). Learned policies are "
        "never loaded from the paths the run records.",
    ),
) -> None:
    """Verify a run: its files against their sha256, then a sample of episodes re-run bit for bit.

    Checks every file of RUN against the sha256 in run_metadata.json (missing, extra and changed
    files are named) and the recorded protocol fingerprint against its id, then re-runs --episodes
    randomly chosen episodes of every policy it can rebuild -- built-ins by name, learned policies
    from --models, user agents from --agent -- with the run's dataset, configuration,
    setting and Planner/Auditor options, and compares each episode's metrics.csv row cell by cell.
    Before re-running, metrics.csv must hold exactly the protocol's rollouts (each policy, run
    seed and episode once) and as many rows as the metadata records. Prints one line per policy
    (verified / differs / cannot rebuild) and a final line with the checksum result and the
    protocol id. Exit status 0 when every rebuilt policy verifies and the checksums and rollouts
    match, 1 on any difference or failure, 2 for unusable arguments.

    A run of another task (evaluate --task) is re-run with the installed task of the name its
    run_metadata.json records (never code the run names); a task not installed here is an error.

    A paper grid root verifies each finished eval unit (learned policies from the grid's own
    models under the root) and the combined files. A suite root verifies each entry's run as a run
    is verified, then its own files against suite_metadata.json and its scores against those
    recomputed from the entries' runs (docs/suites.md). See
    docs/comparing_results.md#verifying-a-run and docs/security.md.
    """
    try:
        specs = [parse_agent_spec(text, known_policies()) for text in agents or []]
        agent_args = parse_agent_args(agent_arg or [], [s.name for s in specs if s.name is not None])
    except ValueError as error:
        raise cli_error(error) from None
    options = VerifyOptions(
        episodes=episodes,
        agents=tuple(agents or ()),
        agent_args=agent_args,
        llm_cache=llm_cache,
        seed=seed,
        data_dir=data_dir,
        models=parse_models(models or []),
    )
    from ..experiments.layout import is_paper_root
    from ..report.suite_loading import is_suite_root

    if run.is_dir() and is_suite_root(run):
        ok = _verify_suite(run, options)
    elif run.is_dir() and is_paper_root(run):
        ok = _verify_grid(run, options)
    else:
        ok = _show(verify_run(run, options))
    if not ok:
        raise typer.Exit(1)


def _show(result: RunVerification, indent: str = "") -> bool:
    for line in result.lines():
        say(indent + line, err=False)
    return result.ok


def _verify_grid(root: Path, options: VerifyOptions) -> bool:
    """Each finished eval unit of a paper root, then its combined files."""
    from dataclasses import replace

    from ..experiments.layout import DONE_MARKER, eval_unit_dirs, is_done
    from ..experiments.units import UNIT_FILE, UNIT_LOG
    from ..report.loading import verify_combined

    if options.agents:
        raise CliError("--agent applies to a single run directory (a grid's units hold built-in policies)")
    units = eval_unit_dirs(root)
    if not units:
        raise CliError(f"{root}: a paper root without eval units (nothing to verify)")
    unit_options = replace(options, grid_files=(UNIT_FILE, UNIT_LOG, DONE_MARKER), models_within=root)
    ok = True
    for unit in units:
        say(f"{unit.relative_to(root)}:", err=False)
        if not is_done(unit):
            say("  not finished (no DONE marker): skipped", err=False)
            continue
        ok = _show(verify_run(unit, unit_options), indent="  ") and ok
    combined = verify_combined(root)
    for problem in combined:
        say(f"checksum: {problem}", err=False)
    say(f"combined files: {'checksums match' if not combined else 'checksums FAIL'}", err=False)
    return ok and not combined


def _verify_suite(root: Path, options: VerifyOptions) -> bool:
    """Each entry's run of a suite root (as a run is verified), then the root's own files and scores."""
    from ..evaluation.suite_run import SUITE_METADATA_FILE
    from ..report.loading import load_report_data
    from ..report.options import ReportDataError
    from ..report.suite_loading import load_suite_data
    from ..report.table_files import read_json

    if options.data_dir is not None:
        raise CliError("--data applies to a single run directory (each entry of a suite has its own dataset)")
    entries = read_json(root / SUITE_METADATA_FILE).get("entries")
    if not isinstance(entries, list) or not all(isinstance(e, dict) and "name" in e for e in entries):
        raise CliError(f"{root / SUITE_METADATA_FILE}: field 'entries' is missing or malformed")
    ok = True
    for entry in entries:
        name = str(entry.get("run_dir", entry["name"]))
        say(f"{name}:", err=False)
        ok = _show(verify_run(root / name, options), indent="  ") and ok
    try:  # the entries' own files were checked above: here only the suite root's
        data = load_suite_data(root, read_run=lambda path: load_report_data(path, allow_unverified=True))
    except ReportDataError as error:
        say(f"suite files: FAIL: {error}", err=False)
        return False
    say(f"suite files: checksums and scores match (suite {data.suite}, suite protocol {data.protocol_id})", err=False)
    return ok
