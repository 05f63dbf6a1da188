"""CLI help and messages as a user sees them at 80 columns: whole option names, plain metavars,
re-flowed paragraphs; text from users, files or servers printed verbatim (no markup, no emoji);
the first use of the default dataset announced."""

from __future__ import annotations

import logging
import re

import pytest
from typer.main import get_command
from typer.testing import CliRunner

from fake_openai import FakeOpenAI, Reply
from solarchain_eval.cli import app

COMMANDS = [
    [],
    ["data"],
    ["data", "build"],
    ["data", "check"],
    ["run"],
    ["evaluate"],
    ["train"],
    ["paper"],
    ["report"],
    ["bench"],
    ["bench-train"],
    ["bench-agent"],
]


def invoke(args, **env):
    return CliRunner().invoke(app, args, env={"COLUMNS": "80", **env}, catch_exceptions=False)


def click_command(path):
    command = get_command(app)
    for name in path:
        command = command.get_command(None, name)  # the top-level group imports a command's module on lookup
    return command


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "root")
def test_help_reads_right_at_80_columns(path):
    result = invoke([*path, "--help"])
    assert result.exit_code == 0, result.output
    text = result.output
    assert max(len(line) for line in text.splitlines()) <= 80, text
    for bad in ("<bool>", "<list[", "…", "[bold]", "\u2011", "range>"):
        assert bad not in text, (bad, text)
    # Every option name appears whole, at the start of its help row.
    for param in click_command(path).params:
        for opt in [*param.opts, *param.secondary_opts]:
            if opt.startswith("--"):
                assert re.search(rf"(^|\s|/ ){re.escape(opt)}(\s|$|,)", text, re.M), (opt, text)
    # Description paragraphs are re-flowed: only a paragraph's last line may be short.
    description = text.split("\n\n", 1)[1].split("Options:")[0].split("Arguments:")[0]
    for paragraph in description.strip().split("\n\n"):
        lines = paragraph.splitlines()
        for line in lines[:-1]:
            assert len(line) >= 50, (line, paragraph)
    # No hyphenated word or option is broken across lines.
    assert not re.search(r"[A-Za-z0-9]-\n", text), text


def test_help_numbers_match_the_readme():
    from collections import Counter

    from solarchain_eval.experiments.grid import GridSpec, plan_units

    kinds = Counter(unit.kind for unit in plan_units(GridSpec(timesteps=300_000, episodes=30, seeds=(1, 2, 3))))
    assert kinds == {"train": 18, "eval": 54}  # the README's "18 models, 54 evaluation units"
    paper = invoke(["paper", "--help"]).output
    assert "18 models" in paper and "54 evaluation units" in paper, paper
    bench = invoke(["bench-train", "--help"]).output
    assert "18 models" in bench and "54 evaluation units" in bench, bench


def test_user_text_is_printed_verbatim_not_as_emoji(tmp_path):
    result = invoke(["data", "build", "--out", str(tmp_path / "d"), "--city", "Foo:100:200"])
    assert result.exit_code == 2
    assert "city 'Foo:100:200'" in result.output and "💯" not in result.output
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("name", ["a[/x]b", "keep [bold]this[/bold] and [redacted]"])
def test_markup_in_paths_and_cells_is_printed_verbatim(tmp_path, name):
    result = invoke(["report", str(tmp_path / name)])
    assert result.exit_code == 2, result.output
    assert name in result.output and "MarkupError" not in result.output
    city = invoke(["data", "build", "--out", str(tmp_path / "d"), "--city", f"{name}:100:200"])
    assert city.exit_code == 2 and f"city '{name}:100:200'" in city.output, city.output


def test_server_error_with_markup_is_printed_verbatim(tiny_dataset, tmp_path, monkeypatch):
    for var in ("SOLARCHAIN_LLM_API_KEY", "OPENAI_API_KEY", "OPENAI_BASE_URL", "SOLARCHAIN_LLM_BASE_URL"):
        monkeypatch.delenv(var, raising=False)
    message = "model [/x] not found; see [bold]docs[/bold] [redacted]"
    script = [Reply(404, {"error": {"message": message, "type": "invalid_request_error"}})] * 4
    with FakeOpenAI(script=script) as server:
        result = invoke(
            [
                "evaluate",
                "--data",
                str(tiny_dataset),
                "--policies",
                "static",
                "--seeds",
                "1",
                "--episodes",
                "1",
                "--out",
                str(tmp_path / "run"),
                "--agentic",
                "planner_auditor",
                "--planner",
                "llm",
                "--llm-api",
                "chat",
                "--llm-model",
                "m",
                "--llm-base-url",
                server.base_url,
                "--llm-max-retries",
                "0",
            ],
            SOLARCHAIN_LLM_API_KEY="sk-test-key",
        )
    assert result.exit_code == 2, result.output
    assert "[/x]" in result.output and "[bold]docs[/bold]" in result.output and "[redacted]" in result.output
    assert "MarkupError" not in result.output and not (tmp_path / "run" / "metrics.csv").exists()


def test_first_default_dataset_build_is_announced(tmp_path, monkeypatch, caplog):
    import solarchain_eval.data.build as build_module
    import solarchain_eval.data.default as default_module
    from solarchain_eval.data.default import default_dataset_dir
    from solarchain_eval.data.files import DATASET_FILES

    def fake_build(weather, out, **kwargs):
        for name in DATASET_FILES:
            (out / name).write_text("")
        (out / "manifest.json").write_text("{}")

    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(build_module, "build_dataset", fake_build)
    monkeypatch.setattr(default_module, "published_mismatches", lambda hashes: {})
    with caplog.at_level(logging.INFO, logger="solarchain_eval"):
        target = default_dataset_dir()
        notices = [r for r in caplog.records if "building the paper's published dataset" in r.getMessage()]
        assert len(notices) == 1 and notices[0].levelno >= logging.WARNING
        assert str(target) in notices[0].getMessage()
        caplog.clear()
        assert default_dataset_dir() == target  # built: no second notice
        assert not [r for r in caplog.records if "building the paper's published dataset" in r.getMessage()]


def test_table_cells_and_progress_text_are_not_markup():
    from rich.table import Table

    from solarchain_eval.cli.common import console, err_console

    table = Table()
    table.add_column("city")
    table.add_row("Foo:100:200 [/x] [bold]B[/bold]")
    for target in (console, err_console):
        with target.capture() as captured:
            target.print(table)
            target.print("path/[/x]/[redacted]")
        out = captured.get()
        assert "Foo:100:200 [/x] [bold]B[/bold]" in out and "💯" not in out and "path/[/x]/[redacted]" in out
