"""Jump-forward decoding of schema-constrained replies, for llama-cpp-python's server.

Grammar-constrained sampling runs the model once per reply token, also for the keys, quotes and
braces the schema forces; those are most of a Planner or Auditor reply. :class:`JumpForwardDecoder`
instead appends each forced text (:mod:`.json_template`) to the context in one batch, which costs
a fraction of one model step per token, and runs the model token by token only inside values,
taking the most likely token that keeps the value valid (greedy decoding; SGLang calls this
jump-forward decoding). Only the last logits of a batch are read, so llama-cpp-python's
``logits_all`` may stay off.

:func:`chat_handler` plugs the decoder into llama-cpp-python as the chat format
:data:`CHAT_FORMAT`: requests at temperature 0 with a ``json_object`` response format whose schema
is a fixed template use it; every other request (sampling, streaming, free text, tools, other
schemas) goes to the model's own chat-template handler, unchanged. See docs/llm.md#speed.
"""

from __future__ import annotations

import ctypes
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .json_template import Literal, Segment, UnsupportedSchema, Value, compile_template

CHAT_FORMAT = "solarchain-jump-forward"
#: Candidates ranked at a time when the most likely token does not fit the value.
_SHORTLIST = 64


@dataclass(frozen=True)
class Reply:
    """A decoded reply: its text, the tokens it took and why it ended (``stop`` or ``length``)."""

    text: str
    completion_tokens: int
    finish_reason: str


class _OutOfTokens(Exception):
    """The token budget ran out mid-template: caught in this module to end decoding.

    Deliberately not a :class:`~solarchain_eval.common.errors.SolarChainError` (a user error): it
    never leaves this module, and one that escaped would be a bug, shown with its traceback.
    """


class JumpForwardDecoder:
    """Fills a :func:`~.json_template.compile_template` template with a llama-cpp-python model.

    Parameters
    ----------
    llama : llama_cpp.Llama
        The model; its context (and KV cache) is reused across calls like
        ``Llama.generate`` does: only the part of a prompt after the prefix it shares with the
        previous call's tokens is evaluated.
    """

    def __init__(self, llama: Any, pieces: list[bytes] | None = None) -> None:
        self.llama = llama
        raw = token_pieces(llama) if pieces is None else pieces
        self.n_vocab = len(raw)
        # A piece that is not whole UTF-8 (byte-fallback tokens) or is a control token is never
        # chosen: every value character comes from a token that is text on its own.
        self.pieces: list[str | None] = []
        for piece in raw:
            try:
                self.pieces.append(piece.decode("utf-8") or None)
            except UnicodeDecodeError:
                self.pieces.append(None)

    def decode(self, prompt_tokens: list[int], segments: list[Segment], max_tokens: int) -> Reply:
        """The reply to ``prompt_tokens`` that follows ``segments``, in at most ``max_tokens`` tokens."""
        llama = self.llama
        if len(prompt_tokens) >= llama.n_ctx():
            raise ValueError(f"Requested tokens ({len(prompt_tokens)}) exceed context window of {llama.n_ctx()}")
        self._pending = self._reuse_prefix(prompt_tokens)
        self._budget = min(max_tokens, llama.n_ctx() - len(prompt_tokens))
        self._used = 0
        parts: list[str] = []
        try:
            for index, segment in enumerate(segments):
                if isinstance(segment, Literal):
                    self._force(segment.text)
                    parts.append(segment.text)
                else:
                    following = next((s.text for s in segments[index + 1 :] if isinstance(s, Literal)), "")
                    self._fill(segment, following, parts)
        except _OutOfTokens:
            return Reply("".join(parts), self._used, "length")
        return Reply("".join(parts), self._used, "stop")

    def _reuse_prefix(self, prompt_tokens: list[int]) -> list[int]:
        """Keep the cached tokens the prompt starts with; return the tokens still to evaluate."""
        llama = self.llama
        cached = llama._input_ids
        shared = 0
        for a, b in zip(cached, prompt_tokens, strict=False):
            if a != b:
                break
            shared += 1
        # At least the last prompt token is evaluated again: its logits are needed.
        shared = min(shared, len(prompt_tokens) - 1)
        if shared > 0 and llama._ctx.kv_cache_seq_rm(-1, shared, -1):
            llama.n_tokens = shared
        else:
            llama.reset()
            shared = 0
        return list(prompt_tokens[shared:])

    def _tokens(self, text: str) -> list[int]:
        return self.llama.tokenize(text.encode("utf-8"), add_bos=False, special=False) if text else []

    def _force(self, text: str) -> None:
        tokens = self._tokens(text)
        if self._used + len(tokens) > self._budget:
            raise _OutOfTokens
        self._used += len(tokens)
        self._pending.extend(tokens)

    def _logits(self) -> np.ndarray:
        """Evaluate the pending tokens in one batch and return the next token's logits."""
        self.llama.eval(self._pending)
        self._pending = []
        # The last token's row (with logits_all the batch has a row per token).
        return np.ctypeslib.as_array(self.llama._ctx.get_logits_ith(-1), shape=(self.n_vocab,))

    def _fill(self, value: Value, following: str, parts: list[str]) -> None:
        text = ""
        while True:
            rest = value.forced_rest(text)
            if rest is not None:
                self._force(rest)
                parts.append(rest)
                return
            if self._used >= self._budget:
                raise _OutOfTokens
            token, extension, ends = self._choose(self._logits(), value, text, following)
            if ends:
                # The chosen token also begins the literal that follows; the literal is forced
                # whole, so only the value's part of the token is added, as its own tokens.
                self._force(extension)
                parts.append(extension)
                return
            self._used += 1
            self._pending.append(token)
            text += extension
            parts.append(extension)

    def _choose(self, logits: np.ndarray, value: Value, text: str, following: str) -> tuple[int, str, bool]:
        """The most likely token that keeps the value valid: ``(token, value text it adds, ends)``."""
        best = int(np.argmax(logits))
        found = self._fit(best, value, text, following)
        if found is not None:
            return best, *found
        shortlist = np.argpartition(logits, -_SHORTLIST)[-_SHORTLIST:]
        ranked = shortlist[np.argsort(-logits[shortlist], kind="stable")]
        for candidates in (ranked, np.argsort(-logits, kind="stable")):
            for token in candidates:
                found = self._fit(int(token), value, text, following)
                if found is not None:
                    return int(token), *found
        raise RuntimeError(f"no token continues the value {text!r}")

    def _fit(self, token: int, value: Value, text: str, following: str) -> tuple[str, bool] | None:
        piece = self.pieces[token]
        if piece is None:
            return None
        if value.accepts(text + piece):
            return piece, False
        # The token ends the value: a (possibly empty) last part of it, then the literal's start.
        for split in range(len(piece) - 1, -1, -1):
            head, tail = piece[:split], piece[split:]
            if (following.startswith(tail) or not following) and value.complete(text + head):
                return head, True
        return None


def token_pieces(llama: Any) -> list[bytes]:
    """The text of every token of ``llama``'s vocabulary (empty for control tokens)."""
    import llama_cpp

    vocab = llama._model.vocab
    pieces = []
    for token in range(int(llama.n_vocab())):
        buffer = ctypes.create_string_buffer(64)
        size = llama_cpp.llama_token_to_piece(vocab, token, buffer, len(buffer), 0, False)
        if size < 0:  # the piece needs -size bytes
            buffer = ctypes.create_string_buffer(-size)
            size = llama_cpp.llama_token_to_piece(vocab, token, buffer, len(buffer), 0, False)
        pieces.append(buffer.raw[:size])
    return pieces


def _formatter_for(llama: Any) -> Any:
    """The model's own chat template (the formatter llama-cpp-python builds from its metadata)."""
    from llama_cpp import llama_chat_format

    template = llama.metadata.get("tokenizer.chat_template")
    if template is None:
        raise UnsupportedSchema("the model has no chat template")
    eos, bos = llama.token_eos(), llama.token_bos()
    return llama_chat_format.Jinja2ChatFormatter(
        template=template,
        eos_token=llama._model.token_get_text(eos) if eos != -1 else "",
        bos_token=llama._model.token_get_text(bos) if bos != -1 else "",
        stop_token_ids=[eos],
    )


def _template_of(response_format: Any) -> list[Segment]:
    if not isinstance(response_format, dict) or response_format.get("type") != "json_object":
        raise UnsupportedSchema("no json_object response format")
    schema = response_format.get("schema")
    if not isinstance(schema, dict):
        raise UnsupportedSchema("no schema")
    return compile_template(schema)


def chat_handler() -> Callable[..., Any]:
    """A llama-cpp-python chat completion handler that jump-forward decodes fixed-template
    JSON replies at temperature 0 and hands every other request to the model's chat template."""
    decoders: dict[int, tuple[JumpForwardDecoder, Any]] = {}

    def handle(*, llama: Any, messages: list[dict[str, Any]], **kwargs: Any) -> Any:
        fallback = llama._chat_handlers.get("chat_template.default")
        try:
            if kwargs.get("stream") or kwargs.get("tools") or kwargs.get("functions"):
                raise UnsupportedSchema("streaming and tools are not jump-forward decoded")
            if float(kwargs.get("temperature", 0.2)) != 0.0:
                raise UnsupportedSchema("sampling is not jump-forward decoded")
            segments = _template_of(kwargs.get("response_format"))
            if id(llama) not in decoders:
                decoders[id(llama)] = (JumpForwardDecoder(llama), _formatter_for(llama))
        except UnsupportedSchema:
            if fallback is None:
                raise
            return fallback(llama=llama, messages=messages, **kwargs)
        decoder, formatter = decoders[id(llama)]
        formatted = formatter(messages=messages)
        prompt = llama.tokenize(formatted.prompt.encode("utf-8"), add_bos=not formatted.added_special, special=True)
        max_tokens = kwargs.get("max_tokens") or llama.n_ctx()
        reply = decoder.decode(prompt, segments, max_tokens)
        return {
            "id": f"chatcmpl-{uuid.uuid4()}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": kwargs.get("model") or llama.model_path,
            "choices": [
                {
                    "index": 0,
                    "message": {"role": "assistant", "content": reply.text},
                    "logprobs": None,
                    "finish_reason": reply.finish_reason,
                }
            ],
            "usage": {
                "prompt_tokens": len(prompt),
                "completion_tokens": reply.completion_tokens,
                "total_tokens": len(prompt) + reply.completion_tokens,
            },
        }

    return handle


def register() -> None:
    """Make :data:`CHAT_FORMAT` a chat format of llama-cpp-python (``--chat_format``)."""
    from llama_cpp import llama_chat_format

    llama_chat_format.LlamaChatCompletionHandlerRegistry().register_chat_completion_handler(
        CHAT_FORMAT, chat_handler(), overwrite=True
    )
