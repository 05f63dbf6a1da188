"""No secret in any output (docs/security.md#no-secret-in-any-output): an HTTP agent spec carrying a
password and a query token goes through evaluate, report, leaderboard and verify, and neither
any file they write nor anything they print holds the secret."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from agent_server import ScriptedAgentServer
from solarchain_eval.cli import app
from solarchain_eval.common.redaction import REDACTED, redact_command, redact_metadata, redact_spec, redact_text
from solarchain_eval.report.loading import load_report_data

PASSWORD, TOKEN, KEY = "hunter2-PASSWORD-x", "tok-SECRET-42", "sk-KEY-0123456789"
SECRETS = (PASSWORD, TOKEN, KEY)


@pytest.fixture
def server():
    server = ScriptedAgentServer()
    yield server
    server.close()


def run_cli(monkeypatch, *args) -> str:
    """Invoke the CLI as a shell would (sys.argv is what a run records); stdout and stderr together."""
    argv = [str(a) for a in args]
    monkeypatch.setattr(sys, "argv", ["solarchain-eval", *argv])
    result = CliRunner().invoke(app, argv, catch_exceptions=False)
    return f"{result.exit_code}\n{result.output}"


def every_file_text(*roots: Path) -> dict[Path, str]:
    return {p: p.read_bytes().decode("utf-8", "replace") for root in roots for p in root.rglob("*") if p.is_file()}


def test_no_output_file_or_stream_holds_the_secret(server, tiny_dataset, tmp_path, monkeypatch):
    url = server.url("/ok").replace("http://", f"http://user:{PASSWORD}@") + f"?token={TOKEN}&api_key={KEY}"
    spec = f"mine={url}"
    run, board = tmp_path / "run", tmp_path / "board"
    printed = [
        run_cli(
            monkeypatch,
            "evaluate",
            "--data",
            tiny_dataset,
            "--policies",
            f"static,{spec}",
            "--seeds",
            5,
            "--episodes",
            2,
            "--out",
            run,
        ),  # fmt: skip
        run_cli(monkeypatch, "report", run, "--no-figures"),
        run_cli(monkeypatch, "leaderboard", run, "--out", board),
        run_cli(monkeypatch, "verify", run, "--episodes", 1, "--seed", 0),
        run_cli(monkeypatch, "verify", run, "--episodes", 1, "--seed", 0, "--agent", spec),
    ]
    assert [p.splitlines()[0] for p in printed] == ["0", "0", "0", "0", "0"], printed
    assert server.seen("/ok"), "the agent was really called"
    meta = json.loads((run / "run_metadata.json").read_text())
    assert meta["policy_specs"][1] == (
        f"mine=http://{REDACTED}@127.0.0.1:{server.server.server_address[1]}/ok?token={REDACTED}&api_key={REDACTED}"
    )
    assert "mine: cannot rebuild (a user agent (mine=http://[redacted]@" in printed[3]
    assert "mine: verified (1 episode; 1 earlier episode(s) replayed in order)" in printed[4]
    files = every_file_text(run, board)
    assert run / "report" / "index.html" in files and board / "leaderboard.csv" in files
    for secret in SECRETS:
        assert [p for p, text in files.items() if secret in text] == []
        assert [text for text in printed if secret in text] == []
    # A run recorded verbatim (as older versions did) is redacted wherever it is shown.
    meta["policy_specs"][1] = spec
    (run / "run_metadata.json").write_text(json.dumps(meta))
    older = [
        run_cli(monkeypatch, "verify", run, "--episodes", 1, "--seed", 0),
        run_cli(monkeypatch, "report", run, "--no-figures", "--out", tmp_path / "report"),
    ]
    assert "mine: cannot rebuild (a user agent (mine=http://[redacted]@" in older[0]
    older.append(json.dumps(load_report_data(run).metadata))  # what the report and the board read
    shown = every_file_text(tmp_path / "report")
    assert tmp_path / "report" / "index.html" in shown
    for secret in SECRETS:
        assert [text for text in older if secret in text] == []
        assert [p for p, text in shown.items() if secret in text] == []


def test_the_cannot_connect_error_does_not_print_the_secret(tiny_dataset, tmp_path, monkeypatch):
    spec = f"mine=http://user:{PASSWORD}@127.0.0.1:9/act?token={TOKEN}"
    printed = run_cli(monkeypatch, "evaluate", "--data", tiny_dataset, "--policies", spec, "--out", tmp_path / "run")
    assert printed.splitlines()[0] == "2"
    assert "cannot connect to 127.0.0.1:9" in printed
    # one line, the URL shown once and redacted, the text after it intact
    assert f"agent 'mine' (http://{REDACTED}@127.0.0.1:9/act?token={REDACTED}): cannot connect" in printed
    assert printed.count("agent 'mine'") == 1
    assert not any(secret in printed for secret in SECRETS)
    assert not (tmp_path / "run").exists()


def test_the_redaction_rules():
    assert (
        redact_spec(f"mine=http://u:{PASSWORD}@h/act?token={TOKEN}") == f"mine=http://{REDACTED}@h/act?token={REDACTED}"
    )
    assert redact_spec("token_agent=agents/a.py:A") == "token_agent=agents/a.py:A"  # a spec's name is not a secret
    assert redact_text(f"--agent-arg api_key={KEY} max_tokens=5") == f"--agent-arg api_key={REDACTED} max_tokens=5"
    assert redact_text(f"Authorization: Bearer {KEY}") == f"Authorization: Bearer {REDACTED}"
    assert redact_command(["evaluate", "--agent-arg", f"mine.api_key={KEY}"])[-1] == f"mine.api_key={REDACTED}"
    old = {"command": ["x", f"--api-key={KEY}"], "policy_specs": [f"m=https://a:{PASSWORD}@h/"], "episodes": 3}
    assert not any(secret in json.dumps(redact_metadata(old)) for secret in SECRETS)
    assert redact_metadata(old)["episodes"] == 3
