"""``python -m solarchain_eval.agentic.model_server [llama-cpp-python server options]``.

llama-cpp-python's OpenAI-compatible server with one more chat format,
:data:`~.jump_forward.CHAT_FORMAT` (jump-forward decoding of schema-constrained replies). Its
options are those of ``python -m llama_cpp.server``; :class:`~.local_server.LocalServer` starts it.
"""

from __future__ import annotations

from .jump_forward import register


def main() -> None:
    register()
    from llama_cpp.server.__main__ import main as serve

    serve()


if __name__ == "__main__":
    main()
