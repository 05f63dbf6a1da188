"""``solarchain-eval evaluate --suite NAME``: run the policies over every entry of a suite and print
the per-entry and aggregate scores (docs/suites.md)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.table import Table

from ..evaluation.agent_setup import check_agents
from ..evaluation.run_spec import EvaluationSpec
from ..evaluation.runner import run_evaluation
from ..evaluation.suite_run import PROFILE_FILE, SUITE_METADATA_FILE, SUITE_SCORES_FILE, SuiteEvaluation, run_suite
from ..evaluation.suite_stats import AGGREGATE_NAMES
from ..tasks.suites import Suite, SuiteEntry
from .common import cli_error, console, invoked_command, say
from .progress import count_progress

_HEADERS = {"iqm": "IQM", "mean": "mean", "median": "median", "optimality_gap": "optimality gap"}


def evaluate_suite(
    suite: Suite,
    make_spec: Callable[[SuiteEntry, Path, list[Any]], EvaluationSpec],
    policies: list[Any],
    out: Path,
    *,
    overwrite: bool,
    step_format: str,
) -> SuiteEvaluation:
    """Check the agents on the first entry, run the suite into ``out`` and print its tables."""
    everyone = suite.with_reference(policies)
    first = suite.entries[0]
    first_spec = make_spec(first, first.data_dir(), everyone)
    try:
        check_agents(first_spec)  # before any work, as evaluate does
    except (ValueError, FileNotFoundError) as error:
        raise cli_error(error) from None
    total = len(suite.entries) * len(everyone) * len(first_spec.run_seeds) * first_spec.episodes
    with count_progress("evaluating", total) as advance:

        def run(spec: EvaluationSpec, run_dir: Path):
            return run_evaluation(
                spec,
                run_dir,
                on_episode=lambda _r: advance(1),
                command=invoked_command(),
                overwrite=overwrite,
                keep_results=False,
                step_format=step_format,
            )

        result = run_suite(suite, policies, make_spec, run, out, overwrite=overwrite, command=invoked_command())
    console.print(task_table(result))
    console.print(aggregate_table(result, suite))
    console.print(improvement_table(result))
    say(f"wrote {len(suite.entries)} runs in {result.wall_s:.1f} s to {out}", err=False)
    for name in (SUITE_SCORES_FILE, PROFILE_FILE, SUITE_METADATA_FILE):
        say(f"  {name:<24} {out / name}", err=False)
    say(
        f"suite protocol {result.protocol_id} (splits {', '.join(result.protocol['splits'])}; equal ids: comparable "
        f"suite results; see {SUITE_METADATA_FILE})",
        err=False,
    )
    return result


def _number(value: float) -> str:
    text = f"{value:.3f}"
    return "0.000" if text == "-0.000" else text  # the reference's own normalised mean, up to rounding


def task_table(result: SuiteEvaluation) -> Table:
    """Per entry: each policy's mean raw score and, after the slash, its mean normalised score."""
    table = Table(title=f"suite {result.suite}: mean score / normalised score per entry", title_justify="left")
    policies = list(dict.fromkeys(result.tasks["policy"]))
    table.add_column("entry")
    table.add_column("split")
    for policy in policies:
        table.add_column(policy, justify="right")
    for (entry, split), group in result.tasks.groupby(["entry", "split"], sort=False):
        cells = {
            row["policy"]: f"{_number(row['score'])} / {_number(row['normalised'])}" for row in group.to_dict("records")
        }
        table.add_row(str(entry), str(split), *(cells.get(policy, "–") for policy in policies))
    return table


def aggregate_table(result: SuiteEvaluation, suite: Suite) -> Table:
    """Per policy: each aggregate of the normalised scores with its 95 % interval."""
    low, high = suite.reference
    table = Table(
        title=f"suite {result.suite}: normalised score (0 = {low}, 1 = {high}), 95 % stratified-bootstrap intervals",
        title_justify="left",
    )
    table.add_column("policy")
    for name in AGGREGATE_NAMES:
        table.add_column(_HEADERS[name], justify="right")
    for row in result.aggregates.to_dict("records"):
        table.add_row(
            str(row["policy"]),
            *(f"{_number(row[n])} [{_number(row[f'{n}_low'])}, {_number(row[f'{n}_high'])}]" for n in AGGREGATE_NAMES),
        )
    return table


def improvement_table(result: SuiteEvaluation) -> Table:
    """P(row policy > column policy), averaged over entries."""
    policies = list(dict.fromkeys(result.improvement["policy"]))
    table = Table(title=f"suite {result.suite}: probability of improvement P(row > column)", title_justify="left")
    table.add_column("policy")
    for policy in policies:
        table.add_column(policy, justify="right")
    cells = {(r["policy"], r["over"]): r["probability"] for r in result.improvement.to_dict("records")}
    for x in policies:
        table.add_row(x, *("–" if x == y else f"{cells[(x, y)]:.3f}" for y in policies))
    return table
