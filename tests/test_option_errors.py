"""Library errors name options by field; the command line shows the same message with flags."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.errors import NamesOptions, flag_of
from solarchain_eval.evaluation.rundir import RunDirError, check_target
from solarchain_eval.governance.request import GovernanceRequest, GovernanceRequestError


def test_field_names_in_the_library_flags_on_the_command_line(tmp_path):
    target = tmp_path / "{opt_x} {0}"  # braces in a value are shown as they are, never parsed
    target.write_text("a file")
    with pytest.raises(RunDirError) as caught:
        check_target(target)
    assert str(caught.value) == f"run_dir {target} is an existing file, not a run directory"
    assert caught.value.message_for({"run_dir": "--out"}.__getitem__).startswith(f"--out {target} is")


def test_governance_request_errors_name_fields():
    with pytest.raises(GovernanceRequestError) as caught:
        GovernanceRequest(planner="llm").resolve()
    assert str(caught.value) == "planner/auditor need agentic planner_auditor"
    assert caught.value.message_for() == "--planner/--auditor need --agentic planner_auditor"
    with pytest.raises(GovernanceRequestError, match="^llm_cache_mode replay needs llm_cache DIR$"):
        GovernanceRequest(
            agentic="planner_auditor", planner="llm", llm_api="chat", llm_model="m", llm_cache_mode="replay"
        ).resolve()


def test_plain_messages_stay_plain():
    error = RunDirError("a {plain} message")
    assert isinstance(error, NamesOptions) and error.message_for() == "a {plain} message"
    assert flag_of("llm_max_output_tokens") == "--llm-max-output-tokens"


def test_cli_shows_flags(tmp_path: Path):
    out = tmp_path / "taken"
    out.write_text("x")
    result = CliRunner().invoke(app, ["evaluate", "--out", str(out), "--episodes", "1"])
    assert result.exit_code == 2
    assert f"--out {out} is an existing file" in " ".join(result.output.split())


@pytest.mark.parametrize(
    ("flag", "value", "kinds"),
    [("--auditor", "wizard", "rule, llm, approve-only"), ("--planner", "wizard", "rule, llm, default")],
)
def test_unknown_planner_or_auditor_names_the_flag(tmp_path: Path, flag, value, kinds):
    out = tmp_path / "run"
    args = ["evaluate", "--agentic", "planner_auditor", flag, value, "--episodes", "1", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    text = " ".join(result.output.split())
    kind = flag.removeprefix("--")
    assert result.exit_code == 2, text
    assert f"{flag}: unknown {kind} '{value}' (choose from {kinds}" in text, text
    assert "LLM settings" not in text and len(result.output.strip().splitlines()) == 1, text
    assert not out.exists()


def test_unknown_planner_or_auditor_names_the_field():
    with pytest.raises(GovernanceRequestError, match=r"^auditor: unknown auditor 'wizard' \(choose from rule, "):
        GovernanceRequest(agentic="planner_auditor", auditor="wizard").resolve()
    with pytest.raises(GovernanceRequestError, match=r"^planner: unknown planner 'wizard' \(choose from rule, "):
        GovernanceRequest(agentic="planner_auditor", planner="wizard", auditor="llm").resolve()
