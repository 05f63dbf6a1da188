"""``solarchain-eval llm serve`` and ``solarchain-eval bench-llm``: the local model server."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator, Mapping
from dataclasses import replace

import typer
from rich.table import Table

from ..governance.request import GovernanceRequest
from ..llm.client import BASE_URL_VARS
from ..llm.serving import local_server
from . import agentic as agentic_cli
from . import app
from .agentic import GOVERNANCE
from .common import CliError, console, err_console, progress_bar, reports_errors

llm_app = typer.Typer(
    help="The local OpenAI-compatible model server (llama-cpp-python). See docs/llm.md.", no_args_is_help=True
)
app.add_typer(llm_app, name="llm")


def _spec(model: str | None, port: int, parallel: int, threads: int | None, decoding: str) -> local_server.ServerSpec:
    if decoding not in local_server.DECODINGS:
        raise CliError(f"--decoding must be one of {', '.join(local_server.DECODINGS)}, got '{decoding}'")
    name, path = local_server.resolve_model(model)
    if path is None:
        path = local_server.default_model_path()  # raises with the install hint
    return local_server.ServerSpec(
        model_path=path,
        model_name=name,
        port=port,
        parallel=parallel,
        threads=local_server.default_threads() if threads is None else threads,
        decoding=decoding,
        requantize=local_server.file_type_for(model),
    )


@contextlib.contextmanager
def _port_named(port: int) -> Iterator[None]:
    """A taken ``--port`` named with the option that picks another; a port picked free
    (``--port 0``) is reported as the library says."""
    try:
        yield
    except local_server.PortInUseError as error:
        if not port or error.port != port:
            raise
        raise CliError(f"port {port} on 127.0.0.1 {error.problem} (choose another with --port)") from None


@llm_app.command("serve")
@reports_errors
def serve(
    model: str | None = typer.Option(
        None,
        "--model",
        help="A GGUF file, served as it is (default: the bundled SmolLM2-135M-Instruct, converted to Q4_0).",
    ),
    port: int = typer.Option(0, "--port", min=0, max=65535, help="Port on 127.0.0.1 (0: a free one)."),
    parallel: int = typer.Option(1, "--parallel", min=1, help="Requests in flight without interrupting each other."),
    threads: int | None = typer.Option(
        None,
        "--threads",
        min=1,
        help="CPU threads of the model (default: the CPUs available, at most 2); 1 on a machine busy with other "
        "work (docs/llm.md#speed).",
    ),
    decoding: str = typer.Option(
        local_server.DEFAULT_DECODING,
        "--decoding",
        help="jump-forward: temperature-0 requests with a json_object schema get the schema's fixed text in "
        "batches and the model runs only inside values; every other request, and all of them with grammar, "
        "are sampled token by token under llama-cpp-python's grammar (docs/llm.md#speed).",
    ),
) -> None:
    """Serve a GGUF model on 127.0.0.1 until Ctrl-C or SIGTERM.

    Waits until the server answers, then prints its base URL and the flags that point
    evaluate/paper at it (--llm-api chat-json-object).
    """
    if port:
        with _port_named(port):
            local_server.check_port(port)  # before the model is looked up or loaded
    spec = _spec(model, port, parallel, threads, decoding)
    err_console.print(f"starting llama-cpp-python's server with {spec.model_path} ...")
    try:
        with _port_named(port), local_server.LocalServer(spec) as server:
            console.print(server.base_url, highlight=False)
            err_console.print(
                f"model '{spec.model_name}' ready; use --llm-base-url {server.base_url} --llm-api "
                f"{local_server.LOCAL_API} "
                f"--llm-model {spec.model_name} --llm-temperature 0 (any API key; other temperatures are sampled "
                "under the grammar, not jump-forward decoded). Ctrl-C stops it.",
                highlight=False,
            )
            while server.process is not None and server.process.poll() is None:
                time.sleep(0.5)
            raise CliError(f"the server exited with status {server.process.returncode if server.process else '?'}")
    except (KeyboardInterrupt, SystemExit):
        err_console.print("server stopped")


BENCH_BACKEND_HELP = (
    "bench-llm's default: remote when an endpoint is given (--llm-base-url, $SOLARCHAIN_LLM_BASE_URL, "
    "$OPENAI_BASE_URL) or --llm-api/--llm-model name a remote API or model, else local (when installed)."
)


def bench_backend(request: GovernanceRequest, *, environ: Mapping[str, str] | None = None) -> str:
    """The backend ``bench-llm`` measures: ``--llm-backend`` when given; else remote when an endpoint
    is (``--llm-base-url`` or its environment variables), or when the options name a remote model
    or API; else the local model, when installed (llama-cpp-python and the model package, or a
    GGUF file given with ``--llm-model``).

    Raises
    ------
    CliError
        None given and none of the two available: says how to get either.
    """
    if request.llm_backend is not None:
        return request.llm_backend
    env = os.environ if environ is None else environ
    if request.llm_base_url is not None or any(env.get(name) for name in BASE_URL_VARS):
        return "remote"
    if request.llm_api is not None and request.llm_api != local_server.LOCAL_API:
        return "remote"  # an API only a remote server speaks
    if request.llm_threads is not None or request.llm_decoding is not None:
        return "local"  # options of the local server (which say what is missing, if anything)
    if local_server.local_model_available(request.llm_model):
        return "local"
    if request.llm_model is not None and not local_server.is_local_model(request.llm_model):
        return "remote"  # a remote model by name, on the default endpoint
    raise CliError(
        "no model to measure: install the local one (pip install -e '.[llm]' in a clone: llama-cpp-python and "
        "the default model) or give an endpoint (--llm-base-url URL or $SOLARCHAIN_LLM_BASE_URL, with --llm-api "
        "and --llm-model)"
    )


@app.command("bench-llm")
@reports_errors
@agentic_cli.governance_options(
    fixed={
        "agentic": "planner_auditor",
        "planner": "llm",
        "auditor": "llm",
        "llm_max_retries": 0,
        "llm_cache": None,
        "llm_cache_mode": "off",
        "diagnostics": None,
    },
    unset={"llm_backend": BENCH_BACKEND_HELP},
)
def bench_llm(
    calls: int = typer.Option(
        4, "--calls", min=1, help="Planner calls (simulated episodes), alternating calm and risky situations."
    ),
    audits_per_plan: int = typer.Option(
        4,
        "--audits-per-plan",
        min=0,
        help="Auditor calls after each planner call, as in an episode (calm and risky steps alternating).",
    ),
    governance: GovernanceRequest = GOVERNANCE,
) -> None:
    """Median and p90 latency per planner and auditor call, tokens/s and schema validity.

    Without an endpoint (--llm-base-url, $SOLARCHAIN_LLM_BASE_URL) it measures the local model,
    when installed (--llm-backend local). With --llm-backend local it also prints the server's CPU seconds per call (steadier than
    latency on a shared machine) and shows what the model answered in a calm and in a risky
    situation, i.e. whether its decisions respond to the risk signals. Nothing is cached.
    Measured figures: docs/performance.md.
    """
    from ..llm import StructuredLLM
    from ..perf.llm_bench import run_llm_bench

    backend = bench_backend(governance)
    if governance.llm_backend is None and backend == "local":
        err_console.print("no endpoint given: measuring the local model (--llm-backend local)")
    governance = replace(governance, llm_backend=backend)
    options = agentic_cli.resolve(governance)
    assert options is not None and options.llm is not None
    with agentic_cli.serving(governance, options) as server:
        client = StructuredLLM(options.llm.settings)
        cpu = server.cpu_seconds if server is not None and server.cpu_seconds() is not None else None
        try:
            with progress_bar("LLM calls", calls * (1 + audits_per_plan)) as advance:
                figures = run_llm_bench(
                    client, calls, audits_per_plan=audits_per_plan, on_call=lambda: advance(1), cpu_seconds=cpu
                )
        finally:
            client.close()
    console.print(
        _bench_table(figures, f"bench-llm: {options.llm.settings.model} via --llm-api {options.llm.settings.api}")
    )
    for kind, fig in figures.items():
        for failure in fig.failures[:3]:
            err_console.print(f"[yellow]invalid {kind} output:[/yellow] {failure}", highlight=False, soft_wrap=True)


def _bench_table(figures, title: str) -> Table:
    from ..perf.llm_bench import RISKS

    table = Table(title=title, title_justify="left")
    columns = ("call", "valid/calls", "median s", "p90 s", "server CPU s (median)", "tokens/s", "prompt tokens")
    for column in (*columns, "completion tokens", *(f"answers ({r})" for r in RISKS)):
        table.add_column(column)

    def fmt(value, spec=".2f"):
        return "-" if value is None else format(value, spec)

    for kind, fig in figures.items():
        s = fig.summary()
        table.add_row(
            kind,
            f"{s['valid']}/{s['calls']}",
            fmt(s["median_s"]),
            fmt(s["p90_s"]),
            fmt(s["median_cpu_s"]),
            fmt(s["tokens_per_s"], ".1f"),
            fmt(s["mean_prompt_tokens"], ".0f"),
            fmt(s["mean_completion_tokens"], ".0f"),
            *("; ".join(sorted(set(fig.answers[r]))) or "-" for r in RISKS),
        )
    return table
