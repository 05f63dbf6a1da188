"""The ``solarchain-eval`` command: one typer app, a module per stage."""

from __future__ import annotations

import importlib

import typer
import typer.main

from .help import HelpGroup, click, make_default_short_help

#: Each command (in ``--help`` order), the module that registers it and its help's first paragraph.
#: ``solarchain-eval --help`` lists these without importing the modules (which load numpy, pandas,
#: pydantic, ...), so it starts fast; a module is imported when its command runs.
#: tests/test_cli_lazy.py checks that these lines match the commands' own help.
COMMANDS = {
    "evaluate": ("evaluate", "Evaluate policies over run seeds × episodes."),
    "run": ("evaluate", "The main job: evaluate the baselines on the embedded default dataset."),
    "train": (
        "train",
        "Train one model with Stable-Baselines3 (MlpPolicy; learning rate, batch size and gamma from "
        "the config: 3e-4, 64, 0.98; SB3 defaults otherwise) and write model.zip, train_config.json, "
        "training_log.csv and train_metadata.json to --out.",
    ),
    "paper": ("paper", "The paper's experiment matrix: train, evaluate, combine, report."),
    "sweep": ("sweep", "Run a sweep: every combination of the YAML's axes is one grid of the `paper` runner."),
    "governance": ("governance", "Score planners and auditors against counterfactual ground truth."),
    "report": (
        "report",
        "Regenerate the paper's tables (Markdown, LaTeX booktabs, CSV) and figures (PNG, SVG) from a "
        "run, with cluster-bootstrap statistics, and write a self-contained ROOT/report/index.html.",
    ),
    "compare": (
        "compare",
        "Compare two runs of the same episodes: mean(OTHER) - mean(BASE) per policy, setting and metric.",
    ),
    "verify": (
        "verify",
        "Verify a run: its files against their sha256, then a sample of episodes re-run bit for bit.",
    ),
    "leaderboard": (
        "leaderboard",
        "Rank runs and paper roots of one protocol per setting, with start-day bootstrap intervals.",
    ),
    "bench": ("bench", "Throughput of the single env, the vector env and the evaluation runner."),
    "bench-train": (
        "bench_train",
        "Measure steady-state SB3 training speed (one torch thread) per algorithm on this env and on "
        "a trivial env with the same spaces, then estimate the paper preset's wall time (300,000 steps, "
        "18 models, 54 evaluation units in 4 settings) on --workers workers by simulating the grid scheduler.",
    ),
    "bench-scale": ("bench_scale", "Scale benchmark: build, load and step synthetic datasets of growing size."),
    "bench-suite": (
        "bench_suite",
        "Time building every shipped offline suite's datasets into a fresh cache and evaluating Static, Random "
        "and Myopic over the held-out suite, each beside a reference on the paper's dataset.",
    ),
    "bench-agent": (
        "bench_agent",
        "Time evaluating the Static baseline, a Python agent object with the same action, that agent "
        "behind HTTP and that agent isolated (--isolate), on the paper's protocol (3 seeds x 30 episodes).",
    ),
    "bench-llm": ("llm", "Median and p90 latency per planner and auditor call, tokens/s and schema validity."),
    "data": ("data", "Build and validate datasets."),
    "llm": ("llm", "The local OpenAI-compatible model server (llama-cpp-python). See docs/llm.md."),
}


class LazyGroup(HelpGroup):
    """The top-level group: imports a command's module only when that command is looked up."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            importlib.import_module(f"{__name__}.{COMMANDS[cmd_name][0]}")  # registers on ``app``
            built = typer.main.get_group(app)
            self.commands.update({name: cmd for name, cmd in built.commands.items() if name not in self.commands})
        return super().get_command(ctx, cmd_name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """click's command list, from :data:`COMMANDS` for commands not imported yet."""
        rows = []
        limit = formatter.width - 6 - max(len(name) for name in COMMANDS)
        for name, (_, first_paragraph) in COMMANDS.items():
            command = self.commands.get(name)
            short = command.get_short_help_str(limit) if command else make_default_short_help(first_paragraph, limit)
            rows.append((name, short))
        with formatter.section("Commands"):
            formatter.write_dl(rows)


app = typer.Typer(
    name="solarchain-eval",
    help=(
        "SolarChain-Eval: a physics-constrained benchmark for trustworthy economic agents in a "
        "decentralised solar-energy market.\n\n"
        "Start with 'solarchain-eval run' (builds the embedded default dataset and "
        "evaluates the baselines), or build the paper's dataset with 'data build'."
    ),
    cls=LazyGroup,
    no_args_is_help=True,
    add_completion=False,
    # Plain click help: re-flowed paragraphs, no markup or emoji codes interpreted in help text.
    rich_markup_mode=None,
    pretty_exceptions_show_locals=False,
)


def _print_version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"solarchain-eval {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False,
        "--version",
        callback=_print_version,
        is_eager=True,
        help="Print the package version and exit.",
    ),
) -> None:
    # An explicit group callback so typer builds the group before any command module has
    # registered its commands; its one option is --version.
    return None


def load_all_commands() -> None:
    """Import every command module (for tools that walk ``app`` itself rather than its click group)."""
    for module in dict.fromkeys(module for module, _ in COMMANDS.values()):
        importlib.import_module(f"{__name__}.{module}")


def main() -> None:
    app()
