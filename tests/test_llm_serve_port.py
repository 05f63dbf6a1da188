"""``llm serve --port P`` on a port already in use names the port (no model needed)."""

from __future__ import annotations

import socket
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.llm.serving import local_server


@pytest.fixture
def occupied() -> Iterator[int]:
    """A port on 127.0.0.1 held (listening) by a plain socket for the test."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield sock.getsockname()[1]


def _error(result) -> str:
    """The command's error line (after "starting ..." if the server was started)."""
    lines = result.output.strip().splitlines()
    assert lines and lines[-1].startswith("error: ") and "error:" not in " ".join(lines[:-1]), result.output
    return lines[-1]


def test_serve_on_a_port_in_use_names_the_port(occupied):
    result = CliRunner().invoke(app, ["llm", "serve", "--port", str(occupied)])
    assert result.exit_code == 2, result.output
    # checked before anything starts: the one line of output, no model needed
    assert result.output.strip() == _error(result), result.output
    assert _error(result) == f"error: port {occupied} on 127.0.0.1 is already in use (choose another with --port)"


@pytest.fixture
def racing(monkeypatch, tmp_path) -> Iterator[tuple[Path, list[socket.socket]]]:
    """A fake server child that finds its port taken: the port is free when checked and taken by
    another process (this test) just before the child starts, which then exits as uvicorn does (3)."""
    held: list[socket.socket] = []

    def command(self) -> list[str]:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.bind(("127.0.0.1", self.port))
        sock.listen()
        held.append(sock)
        return [sys.executable, "-c", "raise SystemExit(3)"]

    monkeypatch.setattr(local_server, "llama_cpp_available", lambda: True)
    monkeypatch.setattr(local_server.LocalServer, "command", command)
    model = tmp_path / "tiny.gguf"
    model.write_bytes(b"GGUF")
    yield model, held
    for sock in held:
        sock.close()


def test_a_port_taken_while_the_server_starts_is_named(racing):
    model, held = racing
    spec = local_server.ServerSpec(model_path=model, model_name="tiny", threads=1)
    with pytest.raises(local_server.PortInUseError) as caught:
        local_server.LocalServer(spec).start(timeout_s=30)
    port = held[0].getsockname()[1]
    assert str(caught.value).endswith(f"port {port} on 127.0.0.1 is already in use by another process"), caught.value


def test_serve_names_a_port_taken_while_it_starts(racing):
    model, held = racing
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # free now; the fake child's command() takes it
    result = CliRunner().invoke(app, ["llm", "serve", "--model", str(model), "--port", str(port), "--threads", "1"])
    assert result.exit_code == 2, result.output
    assert _error(result) == f"error: port {port} on 127.0.0.1 is already in use (choose another with --port)"
