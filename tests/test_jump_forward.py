"""Jump-forward decoding: schema templates, value automata and the decoder, on a scripted model.

The scripted model is a character-level language model that wants to write a given target
reply; the decoder must write it when it is valid, keep the schema when it is not, evaluate the
forced text in batches and reuse the cached prompt prefix. The real model is exercised in
tests/test_llm_local_model.py.
"""

from __future__ import annotations

import ctypes
import json
from decimal import Decimal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from solarchain_eval.config import MarketConfig
from solarchain_eval.governance.schemas import AuditorOutput, PlannerOutput, agent_action_model
from solarchain_eval.llm.response_format import response_format
from solarchain_eval.llm.serving import jump_forward
from solarchain_eval.llm.serving.json_template import (
    Literal,
    UnsupportedSchema,
    Value,
    compile_template,
)
from solarchain_eval.market.actions import ActionCodec

AUDITOR_SCHEMA = response_format(AuditorOutput, "chat-json-object")["schema"]
PLANNER_SCHEMA = response_format(PlannerOutput, "chat-json-object")["schema"]
TEXT = Value("string", max_chars=64, char_class=r"[ !#-\[\]-~]")
RISK = Value("choice", options=("low", "medium", "high", "unknown"))


def test_the_auditor_schema_compiles_to_its_fixed_layout():
    assert compile_template(AUDITOR_SCHEMA) == [
        Literal('{"decision":"'),
        Value("choice", options=("approve", "revise")),
        Literal('","final_action":{"reward_ratio":'),
        Value("number"),
        Literal(',"liquidity_ratio":'),
        Value("number"),
        Literal(',"burn_rate":'),
        Value("number"),
        Literal('},"risk_assessment":{"physics":"'),
        RISK,
        Literal('","liquidity":"'),
        RISK,
        Literal('","jitter":"'),
        RISK,
        Literal('","fairness":"'),
        RISK,
        Literal('"},"reason":"'),
        TEXT,
        Literal('"}'),
    ]


def test_a_filled_planner_template_is_a_valid_planner_output():
    values = iter(["stance", *["0.1", "0.5"] * 3, "0.2", "-0.3", "1", "2", "4", "0.25", "3", "why"])
    text = "".join(s.text if isinstance(s, Literal) else next(values) for s in compile_template(PLANNER_SCHEMA))
    plan = PlannerOutput.model_validate_json(text, strict=True)
    assert plan.audit_policy.max_audits_per_episode == 4 and plan.rationale == "why"


@pytest.mark.parametrize(
    "schema",
    [
        {"anyOf": [{"type": "number"}, {"type": "string"}]},
        {"type": "array", "items": {"type": "number"}},
        {"type": "object", "properties": {"a": {"type": "number"}}, "required": [], "additionalProperties": False},
        {"type": "object", "properties": {"a": {"type": "number"}}, "required": ["a"]},
        {"type": "string", "pattern": "^[a-z]+$"},
        {"type": "string", "pattern": "^[ -~]{0,8}$"},  # admits a quote, which would need escaping
        {"$ref": "#/$defs/Missing"},
        {"type": "null"},
    ],
)
def test_schemas_without_one_layout_are_refused(schema):
    with pytest.raises(UnsupportedSchema):
        compile_template(schema)


@given(st.floats(allow_nan=False, allow_infinity=False, width=32))
def test_every_prefix_of_a_json_number_is_accepted(number):
    text = str(np.float32(number))  # the shortest text of a float32 (up to 9 significant digits)
    value = Value("number")
    assert all(value.accepts(text[:i]) for i in range(len(text) + 1))
    assert value.complete(text)
    assert not value.complete(text + ".") and not value.accepts(text + " ")


@pytest.mark.parametrize("text", ["-", "0.", "1e", "1e+", ".5", "01", "1.2.3", "--1", "1e123", "0." + "1" * 17])
def test_incomplete_or_invalid_numbers_are_not_complete(text):
    assert not Value("number").complete(text)


@given(st.text(max_size=80))
def test_strings_hold_only_their_class_and_length(text):
    allowed = all(" " <= ch <= "~" and ch not in '"\\' for ch in text) and len(text) <= 64
    assert TEXT.accepts(text) == allowed


def test_a_choice_is_forced_once_its_prefix_is_unique():
    assert RISK.forced_rest("m") == "edium"
    assert RISK.forced_rest("") is None
    assert TEXT.forced_rest("x" * 64) == "" and TEXT.forced_rest("x") is None
    assert TEXT.accepts("x" * 64) and not TEXT.accepts("x" * 65)


# --- the decoder on a scripted model -------------------------------------------------------
VOCAB = [b"", *(bytes([c]) for c in range(32, 127)), b'{"', b'":"', b'","', b'"}', b'",', b"0.", b"approve", b"re"]


class ScriptedLlama:
    """A character-level model that wants to write ``target`` after the prompt."""

    def __init__(self, target: str, n_ctx: int = 4096) -> None:
        self.target = target
        self._n_ctx = n_ctx
        self.input_ids: list[int] = []
        self.n_tokens = 0
        self.prompt_length = 0
        self.batches: list[int] = []
        self.logit_reads = 0
        self._logits = np.zeros(len(VOCAB), dtype=np.float32)
        self._ctx = self
        # Fixed small preferences among the tokens the target does not ask for.
        self.noise = np.random.default_rng(0).uniform(0, 1, len(VOCAB)).astype(np.float32)

    # the parts of llama_cpp.Llama the decoder uses
    @property
    def _input_ids(self) -> list[int]:
        return self.input_ids[: self.n_tokens]

    def n_ctx(self) -> int:
        return self._n_ctx

    def reset(self) -> None:
        self.n_tokens = 0

    def kv_cache_seq_rm(self, seq: int, start: int, end: int) -> bool:
        return True

    def tokenize(self, text: bytes, add_bos: bool = False, special: bool = False) -> list[int]:
        tokens, i = [], 0
        while i < len(text):  # longest match
            token = max((t for t, p in enumerate(VOCAB) if p and text.startswith(p, i)), key=lambda t: len(VOCAB[t]))
            tokens.append(token)
            i += len(VOCAB[token])
        return tokens

    def eval(self, tokens: list[int]) -> None:
        assert tokens, "an empty batch"
        del self.input_ids[self.n_tokens :]
        self.input_ids.extend(tokens)
        self.n_tokens += len(tokens)
        self.batches.append(len(tokens))

    def get_logits_ith(self, index: int):
        assert index == -1
        self.logit_reads += 1
        written = b"".join(VOCAB[t] for t in self.input_ids[self.prompt_length : self.n_tokens]).decode()
        self._logits[:] = self.noise
        if self.target.startswith(written):
            rest = self.target[len(written) :].encode()
            wanted = [t for t, p in enumerate(VOCAB) if p and rest.startswith(p)]
            if wanted:
                self._logits[max(wanted, key=lambda t: len(VOCAB[t]))] = 10.0
        return self._logits.ctypes.data_as(ctypes.POINTER(ctypes.c_float))


def _decode(target: str, schema=AUDITOR_SCHEMA, max_tokens: int = 512, prompt: str = "PROMPT:"):
    llama = ScriptedLlama(target)
    decoder = jump_forward.JumpForwardDecoder(llama, pieces=VOCAB)
    prompt_tokens = llama.tokenize(prompt.encode())
    llama.prompt_length = len(prompt_tokens)
    return decoder.decode(prompt_tokens, compile_template(schema), max_tokens), llama


VALID_AUDIT = (
    '{"decision":"revise","final_action":{"reward_ratio":0.25,"liquidity_ratio":0.5,"burn_rate":0.05},'
    '"risk_assessment":{"physics":"high","liquidity":"low","jitter":"medium","fairness":"unknown"},'
    '"reason":"too much unbacked supply"}'
)


def test_a_valid_target_is_written_exactly_with_forced_text_in_batches():
    reply, llama = _decode(VALID_AUDIT)
    assert reply.text == VALID_AUDIT and reply.finish_reason == "stop"
    assert AuditorOutput.model_validate_json(reply.text, strict=True).reason == "too much unbacked supply"
    # One evaluation per logits read (nothing evaluated twice), the whole reply's tokens but
    # the closing literal evaluated, and far fewer evaluations than tokens.
    assert len(llama.batches) == llama.logit_reads
    assert sum(llama.batches) == len(llama.tokenize(b"PROMPT:" + VALID_AUDIT.encode()[:-2]))
    assert reply.completion_tokens == len(llama.tokenize(VALID_AUDIT.encode()))
    # Model steps: "re" makes the decision unique (1); "0." "2" "5" then "," ends 0.25 (4), 0.5 (3),
    # 0.05 (4); one letter makes each risk level unique (4); 24 reason characters and the end (25).
    assert len(llama.batches) == 1 + 4 + 3 + 4 + 4 + 25 < reply.completion_tokens


@pytest.mark.parametrize(
    ("bad", "check"),
    [
        # a space inside a number: the scripted model has no wish after it, and its weakest
        # wishes run the number to the digit limits, which must still be a finite number
        ('"reward_ratio":0.2 5', lambda out: np.isfinite(out.final_action.reward_ratio)),
        ('"decision":"reject"', lambda out: out.decision == "revise"),  # "re" then forced to revise
        ('"physics":"severe"', lambda out: out.risk_assessment.physics in ("low", "medium", "high", "unknown")),
        ('"reason":"say \\"no\\""', lambda out: '"' not in out.reason and "\\" not in out.reason),
    ],
)
def test_an_invalid_wish_of_the_model_still_gives_a_valid_reply(bad, check):
    key = bad.split(":")[0]
    start = VALID_AUDIT.index(key)
    end = VALID_AUDIT.index(",", start) if key != '"reason"' else len(VALID_AUDIT) - 1
    target = VALID_AUDIT[:start] + bad + VALID_AUDIT[end:]
    reply, _ = _decode(target)
    assert check(AuditorOutput.model_validate_json(reply.text, strict=True))


def test_free_text_stops_at_its_maximum_length():
    target = VALID_AUDIT.replace("too much unbacked supply", "x" * 100)
    reply, _ = _decode(target)
    assert AuditorOutput.model_validate_json(reply.text, strict=True).reason == "x" * 64


def test_the_token_budget_ends_a_reply_with_length():
    reply, _ = _decode(VALID_AUDIT, max_tokens=12)
    assert reply.finish_reason == "length" and reply.completion_tokens <= 12
    assert VALID_AUDIT.startswith(reply.text)


def test_a_second_request_evaluates_only_what_follows_the_shared_prefix():
    llama = ScriptedLlama(VALID_AUDIT)
    decoder = jump_forward.JumpForwardDecoder(llama, pieces=VOCAB)
    template = compile_template(AUDITOR_SCHEMA)
    first = llama.tokenize(b"SYSTEM PROMPT; step 1:")
    llama.prompt_length = len(first)
    decoder.decode(first, template, 512)
    second = llama.tokenize(b"SYSTEM PROMPT; step 2:")
    llama.prompt_length = len(second)
    llama.batches.clear()
    reply = decoder.decode(second, template, 512)
    assert reply.text == VALID_AUDIT
    assert llama.batches[0] == len(llama.tokenize(b'2:{"decision":"'))


def _fake_llama_for_handler(default):
    class Handlerless(ScriptedLlama):
        _chat_handlers = {"chat_template.default": default}

    return Handlerless(VALID_AUDIT)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"temperature": 0.7, "response_format": {"type": "json_object", "schema": AUDITOR_SCHEMA}},
        {"temperature": 0.0},
        {"temperature": 0.0, "response_format": {"type": "json_schema", "json_schema": {"schema": AUDITOR_SCHEMA}}},
        {"temperature": 0.0, "response_format": {"type": "json_object", "schema": {"type": "array"}}},
        {"temperature": 0.0, "stream": True, "response_format": {"type": "json_object", "schema": AUDITOR_SCHEMA}},
    ],
)
def test_other_requests_go_to_the_models_own_chat_template(kwargs):
    calls = []
    llama = _fake_llama_for_handler(lambda **kw: calls.append(kw) or "the default handler's answer")
    answer = jump_forward.chat_handler()(llama=llama, messages=[{"role": "user", "content": "hi"}], **kwargs)
    assert answer == "the default handler's answer" and calls[0]["messages"][0]["content"] == "hi"


@settings(max_examples=30, deadline=None)
@given(
    st.floats(0, 1, width=32),
    st.sampled_from(["low", "medium", "high", "unknown"]),
    st.text(st.characters(min_codepoint=32, max_codepoint=126, blacklist_characters='"\\'), max_size=64),
)
def test_any_valid_audit_the_model_wants_is_written_as_it_wants(ratio, risk, reason):
    target = json.loads(VALID_AUDIT)
    target["final_action"]["liquidity_ratio"] = round(ratio, 6)
    target["risk_assessment"]["jitter"] = risk
    target["reason"] = reason
    text = json.dumps(target, separators=(",", ":"))
    reply, _ = _decode(text)
    assert reply.text == text


# --- numbers with minimum and maximum (the LLM agent's action) ------------------------------
AGENT_SCHEMA = response_format(agent_action_model(ActionCodec.from_config(MarketConfig())), "chat-json-object")[
    "schema"
]


def test_a_bounded_schema_compiles_to_bounded_number_slots():
    assert compile_template(AGENT_SCHEMA) == [
        Literal('{"reward_ratio":'),
        Value("number", minimum="0.05", maximum="0.65"),
        Literal(',"liquidity_ratio":'),
        Value("number", minimum="0.2", maximum="0.95"),
        Literal(',"burn_rate":'),
        Value("number", minimum="0.0", maximum="0.2"),
        Literal("}"),
    ]


@settings(max_examples=200, deadline=None)
@given(
    st.decimals(-1000, 1000, places=3, allow_nan=False, allow_infinity=False),
    st.decimals(-1000, 1000, places=2, allow_nan=False, allow_infinity=False),
    st.decimals(0, 500, places=2, allow_nan=False, allow_infinity=False),
    st.sampled_from(["number", "integer"]),
)
def test_a_bounded_number_admits_exactly_the_prefixes_of_values_inside_its_bounds(value, low, width, kind):
    if kind == "integer":
        value = value.to_integral_value()
    slot = Value(kind, minimum=str(low), maximum=str(low + width))
    text = format(value, "f")
    inside = low <= value <= low + width
    assert slot.complete(text) == inside
    if inside:  # every prefix of a value inside stays open
        assert all(slot.accepts(text[:i]) for i in range(len(text) + 1))
    # whatever is accepted can still be completed inside the bounds by appending one digit at a time
    prefix = text[: len(text) // 2]
    if slot.accepts(prefix):
        for _ in range(40):
            if slot.complete(prefix):
                break
            prefix += next(ch for ch in "-0123456789." if slot.accepts(prefix + ch))
        assert slot.complete(prefix) and low <= Decimal(prefix) <= low + width


def test_a_bounded_number_never_takes_an_exponent_or_leaves_its_integers():
    slot = Value("number", minimum="0.05", maximum="0.65")
    assert slot.accepts("0.0") and not slot.accepts("0.04") and not slot.accepts("0.7") and not slot.accepts("1")
    assert not slot.complete("5e-2") and not slot.accepts("5e")
    assert Value("integer", minimum="-3", maximum="12").accepts("1") and not Value("integer", maximum="12").accepts(
        "13"
    )
    with pytest.raises(UnsupportedSchema):  # no integer between the bounds
        compile_template({"type": "integer", "minimum": 0.5, "maximum": 0.7})
    for schema in ({"type": "number", "exclusiveMinimum": 0}, {"type": "number", "minimum": 2, "maximum": 1}):
        with pytest.raises(UnsupportedSchema):
            compile_template(schema)


@pytest.mark.parametrize(
    "wish",
    [
        '{"reward_ratio":0.9,"liquidity_ratio":1.5,"burn_rate":0.5}',  # each above its maximum
        '{"reward_ratio":0.01,"liquidity_ratio":-1,"burn_rate":-0.1}',  # each below its minimum
        '{"reward_ratio":6.5e-1,"liquidity_ratio":0.20,"burn_rate":2e-1}',  # exponents
    ],
)
def test_a_model_that_wants_values_out_of_range_still_writes_values_inside(wish):
    reply, _ = _decode(wish, schema=AGENT_SCHEMA)
    assert reply.finish_reason == "stop"
    model = agent_action_model(ActionCodec.from_config(MarketConfig()))
    action = model.model_validate_json(reply.text)  # validates the bounds
    assert 0.05 <= action.reward_ratio <= 0.65 and 0.2 <= action.liquidity_ratio <= 0.95


def test_a_wish_inside_the_bounds_is_written_as_it_is():
    wish = '{"reward_ratio":0.25,"liquidity_ratio":0.7,"burn_rate":0.05}'
    assert _decode(wish, schema=AGENT_SCHEMA)[0].text == wish
