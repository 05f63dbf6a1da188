"""Attack patterns (data/fdia.py) and episode-seed rules (protocol.py) are defined once; the CLI's
choices and help and the sweep YAML's validator derive from that one definition."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
import typing

from typer.testing import CliRunner

from solarchain_eval.data.fdia import FDIA_PATTERN_LINES, FDIA_PATTERNS, fdia_pattern_help
from solarchain_eval.experiments.sweep_spec import SweepDataset, SweepGrid
from solarchain_eval.protocol import EPISODE_SEED_RULE_LINES, EPISODE_SEED_RULES, episode_seed_derivation


def _help(command, option):
    """The help typer shows for ``option`` of ``command`` (from the option's declaration)."""
    return inspect.signature(command).parameters[option].default.help


def test_the_derived_lists_are_the_one_definition():
    from solarchain_eval.cli.data import FdiaPattern
    from solarchain_eval.cli.paper import EpisodeSeeds

    assert tuple(FDIA_PATTERN_LINES) == FDIA_PATTERNS == ("uniform", "clustered", "stealthy")
    assert tuple(p.value for p in FdiaPattern) == FDIA_PATTERNS
    assert typing.get_args(SweepDataset.model_fields["fdia_pattern"].annotation) == FDIA_PATTERNS
    assert set(EPISODE_SEED_RULE_LINES) == set(EPISODE_SEED_RULES) == {"paper", "independent"}
    assert tuple(e.value for e in EpisodeSeeds) == tuple(EPISODE_SEED_RULES)
    assert typing.get_args(SweepGrid.model_fields["episode_seeds"].annotation) == tuple(EPISODE_SEED_RULES)


def test_the_cli_help_is_the_definitions_lines_as_before():
    from solarchain_eval.cli.data import build
    from solarchain_eval.cli.paper import paper

    pattern_help = _help(build, "fdia_pattern")
    assert pattern_help == fdia_pattern_help("--fdia-burst-hours")
    assert pattern_help.startswith("uniform: records drawn uniformly (the paper's). clustered: bursts of ")
    assert "stealthy: daylight records reported at min(m, 1) x P_max" in pattern_help
    assert _help(paper, "episode_seeds") == (
        "paper: episode e of seed s uses s + e (seeds share episodes). "
        "independent: non-overlapping seeds from a SeedSequence."
    )


def test_unknown_names_are_refused_with_the_definitions_choices(tmp_path):
    from solarchain_eval.cli import app

    result = CliRunner().invoke(app, ["data", "build", "--out", str(tmp_path / "d"), "--fdia-pattern", "ramp"])
    assert result.exit_code == 2
    assert "'uniform', 'clustered', 'stealthy'" in " ".join(result.output.split())
    assert not (tmp_path / "d").exists()


def test_the_episode_seed_derivation_recorded_in_a_paper_root():
    assert episode_seed_derivation("paper") == "episode e of run seed s is reset with seed s + e"
    independent = episode_seed_derivation("independent")
    assert independent.startswith("Episode ``e`` of run seed ``s`` is reset with word ``e`` of")
    assert independent.endswith("which the grid checks anyway.")


#: A pattern and a rule added to their one definition, before anything else imports them.
_ADD = """
import json
import solarchain_eval.data.fdia as fdia
import solarchain_eval.protocol as protocol

fdia.FDIA_PATTERN_LINES["ramp"] = "a ramp."
fdia.FDIA_PATTERNS = tuple(fdia.FDIA_PATTERN_LINES)
protocol.EPISODE_SEED_RULES["reversed"] = lambda s, n: [s + n - 1 - e for e in range(n)]
protocol.EPISODE_SEED_RULE_LINES["reversed"] = "the paper's seeds backwards."

import inspect
from solarchain_eval.cli.data import FdiaPattern, build
from solarchain_eval.cli.paper import EpisodeSeeds, paper
from solarchain_eval.experiments.sweep_spec import SweepDataset, SweepGrid

def help(command, option):
    return inspect.signature(command).parameters[option].default.help

print(json.dumps({
    "cli_patterns": [p.value for p in FdiaPattern],
    "cli_pattern_help": help(build, "fdia_pattern"),
    "sweep_pattern": SweepDataset(fdia_pattern="ramp").fdia_pattern,
    "cli_rules": [e.value for e in EpisodeSeeds],
    "cli_rule_help": help(paper, "episode_seeds"),
    "sweep_rule": SweepGrid(episode_seeds="reversed").episode_seeds,
}))
"""


def test_a_pattern_or_rule_added_to_its_definition_reaches_the_cli_and_the_sweep():
    done = subprocess.run([sys.executable, "-c", _ADD], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["cli_patterns"] == ["uniform", "clustered", "stealthy", "ramp"]
    assert seen["cli_pattern_help"].endswith(" ramp: a ramp.")
    assert seen["sweep_pattern"] == "ramp"
    assert seen["cli_rules"] == ["paper", "independent", "reversed"]
    assert seen["cli_rule_help"].endswith(" reversed: the paper's seeds backwards.")
    assert seen["sweep_rule"] == "reversed"
