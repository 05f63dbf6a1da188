"""``python -m solarchain_eval.llm.serving.model_server [--requantize TYPE] [llama-cpp-python server options]``.

llama-cpp-python's OpenAI-compatible server with one more chat format,
:data:`~.jump_forward.CHAT_FORMAT` (jump-forward decoding of schema-constrained replies), behind
:class:`~.openai_compat.OpenAICompat` (``json_schema`` response formats as the OpenAI SDK's
``.parse()`` sends them, and HTTP 400 with OpenAI's error body for a malformed request). Its
options are those of ``python -m llama_cpp.server`` (command-line options only: no config file);
:class:`~.local_server.LocalServer` starts it.

``--requantize Q4_0 [--requantize_dir DIR]`` first converts the ``--model`` file to that llama.cpp
type in DIR (which the caller deletes: :class:`~.local_server.LocalServer` does when it stops the
server, however the server ends) or else in a temporary directory deleted when the server returns,
and serves the copy: the default model ships as Q4_1,
and llama.cpp's CPU kernels for Q4_0 (repacked for AVX2/AVX-512) read a prompt about twice as fast
(docs/llm.md#speed). The conversion takes about a second and gives the same file every time.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import logging
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .jump_forward import register
from .openai_compat import OpenAICompat, llama_cpp_checks

#: llama.cpp file types (``enum llama_ftype``) ``--requantize`` converts to.
FILE_TYPES = {"Q4_0": 2, "Q8_0": 7}


def requantize(source: Path, target: Path, file_type: str) -> None:
    """Write ``source`` converted to ``file_type`` (a key of :data:`FILE_TYPES`) to ``target``."""
    import llama_cpp

    params = llama_cpp.llama_model_quantize_default_params()
    params.ftype = FILE_TYPES[file_type]
    params.allow_requantize = True
    logger = logging.getLogger("llama-cpp-python")  # llama.cpp prints a line per tensor otherwise
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        status = llama_cpp.llama_model_quantize(str(source).encode(), str(target).encode(), ctypes.byref(params))
    finally:
        logger.setLevel(level)
    if status != 0:
        raise RuntimeError(f"llama.cpp could not convert {source} to {file_type} (status {status})")


def _pop_option(args: list[str], name: str) -> str | None:
    if name not in args:
        return None
    at = args.index(name)
    value = args[at + 1]
    del args[at : at + 2]
    return value


@contextlib.contextmanager
def served_arguments(args: list[str]) -> Iterator[list[str]]:
    """The server's arguments with ``--requantize`` applied: ``--model`` points at the converted
    copy (in ``--requantize_dir``, else in a temporary directory deleted on exit)."""
    rest = list(args)
    file_type, folder = _pop_option(rest, "--requantize"), _pop_option(rest, "--requantize_dir")
    if file_type is None:
        yield rest
        return
    if file_type not in FILE_TYPES:
        raise SystemExit(f"--requantize must be one of {', '.join(FILE_TYPES)}, got {file_type!r}")
    source = Path(rest[rest.index("--model") + 1])
    with contextlib.ExitStack() as stack:
        if folder is None:
            folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="solarchain-model-"))
        target = Path(folder) / f"{source.stem.rsplit('.', 1)[0]}.{file_type}.gguf"
        requantize(source, target, file_type)
        rest[rest.index("--model") + 1] = str(target)
        yield rest


def serve(args: list[str]) -> None:
    """Run llama-cpp-python's server app for the options ``args``, behind :class:`OpenAICompat`."""
    import uvicorn
    from llama_cpp.server.app import create_app
    from llama_cpp.server.cli import add_args_from_model, parse_model_from_args
    from llama_cpp.server.settings import ModelSettings, ServerSettings, Settings

    parser = argparse.ArgumentParser(prog="python -m solarchain_eval.llm.serving.model_server")
    add_args_from_model(parser, Settings)
    options = parser.parse_args(args)
    server_settings = parse_model_from_args(ServerSettings, options)
    model_settings = parse_model_from_args(ModelSettings, options)
    app = create_app(server_settings=server_settings, model_settings=[model_settings])
    uvicorn.run(
        # n_ctx 0 takes the model's own window, unknown here: max_tokens is then not checked against it.
        OpenAICompat(app, **llama_cpp_checks(), context_tokens=model_settings.n_ctx or None),
        host=server_settings.host,
        port=server_settings.port,
        ssl_keyfile=server_settings.ssl_keyfile,
        ssl_certfile=server_settings.ssl_certfile,
    )


def main() -> None:
    register()
    with served_arguments(sys.argv[1:]) as args:
        serve(args)


if __name__ == "__main__":
    main()
