"""The ``solarchain-eval`` command: one typer app, a module per stage."""

from __future__ import annotations

import typer

from .help import HelpGroup

app = typer.Typer(
    name="solarchain-eval",
    help=(
        "SolarChain-Eval: a physics-constrained benchmark for trustworthy economic agents in a "
        "decentralised solar-energy market.\n\n"
        "Start with 'solarchain-eval run' (builds the embedded default dataset and "
        "evaluates the baselines), or build the paper's dataset with 'data build'."
    ),
    cls=HelpGroup,
    no_args_is_help=True,
    add_completion=False,
    # Plain click help: re-flowed paragraphs, no markup or emoji codes interpreted in help text.
    rich_markup_mode=None,
    pretty_exceptions_show_locals=False,
)

# Command modules register themselves on `app`, in the order of the pipeline (which is the order
# `--help` lists them in, so the block is kept out of import sorting).
# isort: off
from . import data as _data  # noqa: E402, F401
from . import evaluate as _evaluate  # noqa: E402, F401
from . import train as _train  # noqa: E402, F401
from . import paper as _paper  # noqa: E402, F401
from . import sweep as _sweep  # noqa: E402, F401
from . import report as _report  # noqa: E402, F401
from . import bench as _bench  # noqa: E402, F401
from . import bench_train as _bench_train  # noqa: E402, F401
from . import bench_scale as _bench_scale  # noqa: E402, F401
from . import llm as _llm  # noqa: E402, F401
# isort: on


def main() -> None:
    app()
