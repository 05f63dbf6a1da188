"""``solarchain-eval --help`` and ``import solarchain_eval.report`` stay light.

The top-level help lists the commands from ``cli.COMMANDS`` without importing their modules;
these tests check that it imports none of the heavy libraries, that the listed help matches
each command's own, and that the report package does not load the dataset build's pvlib.
"""

from __future__ import annotations

import subprocess
import sys

import typer.main

from solarchain_eval import cli

HEAVY = ("pandas", "scipy", "matplotlib", "pvlib", "torch", "stable_baselines3", "httpx", "solarchain_eval.experiments")


def loaded_after(code: str) -> list[str]:
    """The HEAVY modules loaded after running ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport sys\nprint(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return eval(out.stdout.strip().splitlines()[-1])  # noqa: S307 - our own probe's repr of a list of names


def test_top_level_help_imports_no_heavy_module():
    code = (
        "import sys\nsys.argv = ['solarchain-eval', '--help']\nfrom solarchain_eval.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass"
    )
    assert loaded_after(code) == []


def test_report_package_does_not_import_pvlib():
    assert "pvlib" not in loaded_after("import solarchain_eval.report")


def test_listed_help_matches_each_command():
    cli.load_all_commands()
    group = typer.main.get_group(cli.app)
    assert list(group.commands) == sorted(cli.COMMANDS, key=list(group.commands).index)  # no command unlisted
    assert set(group.commands) == set(cli.COMMANDS)
    for name, (module, first_paragraph) in cli.COMMANDS.items():
        command = group.commands[name]
        assert " ".join(command.help.split("\n\n")[0].split()) == first_paragraph, name
        callback = command.callback if command.callback is not None else next(iter(command.commands.values())).callback
        assert callback.__module__ == f"solarchain_eval.cli.{module}", name


def test_report_help_imports_no_heavy_module():
    code = (
        "import sys\nsys.argv = ['solarchain-eval', 'report', '--help']\nfrom solarchain_eval.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass"
    )
    assert [m for m in loaded_after(code) if m in ("pandas", "scipy", "matplotlib")] == []


def test_report_exports_resolve_lazily_to_their_one_definition():
    import solarchain_eval.report as report
    import solarchain_eval.report.leaderboard as leaderboard
    from solarchain_eval.report import loading, options
    from solarchain_eval.report.leaderboard import make
    from solarchain_eval.report.paper import build

    assert set(report.__all__) == set(report._EXPORTS)
    assert report.build_report is build.build_report and report.ReportDataError is loading.ReportDataError
    assert report.FORMATS is options.FORMATS
    assert set(leaderboard.__all__) == set(leaderboard._EXPORTS)
    assert leaderboard.make_leaderboards is make.make_leaderboards
    assert leaderboard.LeaderboardOutcome is make.LeaderboardOutcome
