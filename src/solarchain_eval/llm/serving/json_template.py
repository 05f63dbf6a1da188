"""A strict JSON schema as a template: the text it forces, and the values a model must choose.

A strict schema (every property required, in a fixed order, no alternatives) fixes every
character of a compact reply except its values: ``{"decision": "`` is the same in every Auditor
reply. :func:`compile_template` turns such a schema into a list of :class:`Literal` texts and
:class:`Value` slots; :mod:`.jump_forward` appends each literal to the model's context in one batch
and lets the model choose only the values, one token at a time, each checked by its slot's
:meth:`Value.accepts`. The replies are compact JSON ("," and ":" separators, no spaces).

Supported: objects (nested or by ``$ref`` into ``$defs``), strings (with ``enum``, ``maxLength``
and a ``pattern`` of the form ``^[class]{0,N}$``), numbers, integers, booleans and ``enum``/``const``
of those. Anything else raises :class:`UnsupportedSchema`, and the server answers that request
with llama-cpp-python's grammar-constrained sampling instead.
"""

from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass
from typing import Any

#: Digits allowed in a number's integer part, fraction and exponent: those of llama.cpp's JSON
#: grammar (``[1-9] [0-9]{0,15}`` and ``[0-9]{1,16}``), so a greedy model repeating a digit must
#: still end the value, and a two-digit exponent, so every number is a finite double.
MAX_INTEGER_DIGITS = 16
MAX_FRACTION_DIGITS = 16
MAX_EXPONENT_DIGITS = 2

_DIGITS = rf"(?:0|[1-9][0-9]{{0,{MAX_INTEGER_DIGITS - 1}}})"
_INT = rf"-?{_DIGITS}"
_FRACTION = rf"\.[0-9]{{1,{MAX_FRACTION_DIGITS}}}"
_EXPONENT = rf"[eE][-+]?[0-9]{{1,{MAX_EXPONENT_DIGITS}}}"
#: Every prefix of an integer (the sign alone, or part of its digits).
_INT_PREFIX = rf"-?{_DIGITS}?\Z"
#: For ``number`` and ``integer`` slots: (every prefix of a value, a whole value). A number's
#: prefixes are three alternatives: in the integer part, the fraction, the exponent.
_NUMERIC = {
    "integer": (re.compile(_INT_PREFIX), re.compile(rf"{_INT}\Z")),
    "number": (
        re.compile(
            rf"{_INT_PREFIX}"
            rf"|{_INT}\.[0-9]{{0,{MAX_FRACTION_DIGITS}}}\Z"
            rf"|{_INT}(?:{_FRACTION})?[eE][-+]?[0-9]{{0,{MAX_EXPONENT_DIGITS}}}\Z"
        ),
        re.compile(rf"{_INT}(?:{_FRACTION})?(?:{_EXPONENT})?\Z"),
    ),
}
#: The one ``pattern`` form understood: a character class repeated 0..N times.
_CLASS_PATTERN = re.compile(r"\^(\[[^\]\\]*(?:\\.[^\]\\]*)*\])\{0,(\d+)\}\$\Z")


@functools.cache
def _char_run(char_class: str) -> re.Pattern[str]:
    return re.compile(f"{char_class}*")


class UnsupportedSchema(ValueError):
    """The schema is not a fixed template (alternatives, arrays, optional keys, ...)."""


@dataclass(frozen=True)
class Literal:
    """Text every reply has at this point."""

    text: str


@dataclass(frozen=True)
class Value:
    """A slot the model fills: the raw JSON text of a number or boolean, or a string's content
    (the quotes belong to the neighbouring literals).

    Parameters
    ----------
    kind : {"number", "integer", "string", "choice"}
        ``choice`` is one of ``options`` (an ``enum``, ``const`` or boolean).
    max_chars : int or None
        A string's ``maxLength``.
    char_class : str or None
        A regular-expression character class every string character must match; None admits any
        character but ``"``, ``\\`` and control characters (so no escapes are ever written).
    options : tuple of str
        The texts a ``choice`` may take.
    """

    kind: str
    max_chars: int | None = None
    char_class: str | None = None
    options: tuple[str, ...] = ()

    def accepts(self, text: str) -> bool:
        """Whether ``text`` can begin (or be) a value of this slot."""
        if self.kind in _NUMERIC:
            return _NUMERIC[self.kind][0].match(text) is not None
        if self.kind == "choice":
            return any(option.startswith(text) for option in self.options)
        if self.max_chars is not None and len(text) > self.max_chars:
            return False
        if self.char_class is not None:
            return _char_run(self.char_class).fullmatch(text) is not None
        return all(ch not in '"\\' and ord(ch) >= 0x20 for ch in text)

    def complete(self, text: str) -> bool:
        """Whether ``text`` is a whole value of this slot."""
        if self.kind in _NUMERIC:
            return _NUMERIC[self.kind][1].match(text) is not None
        if self.kind == "choice":
            return text in self.options
        return self.accepts(text)

    def forced_rest(self, text: str) -> str | None:
        """The rest of the value when ``text`` leaves no choice (a unique choice, a full string),
        else None."""
        if self.kind == "choice":
            matches = [option for option in self.options if option.startswith(text)]
            if len(matches) == 1:
                return matches[0][len(text) :]
        if self.kind == "string" and self.max_chars is not None and len(text) == self.max_chars:
            return ""
        return None


Segment = Literal | Value


def compile_template(schema: dict[str, Any]) -> list[Segment]:
    """The literals and value slots of ``schema``'s replies, adjacent literals merged.

    Raises
    ------
    UnsupportedSchema
        ``schema`` allows more than one layout.
    """
    segments: list[Segment] = []
    _emit(schema, schema.get("$defs", {}), segments)
    merged: list[Segment] = []
    for segment in segments:
        if isinstance(segment, Literal) and merged and isinstance(merged[-1], Literal):
            merged[-1] = Literal(merged[-1].text + segment.text)
        else:
            merged.append(segment)
    return merged


def _emit(schema: Any, defs: dict[str, Any], out: list[Segment]) -> None:
    if not isinstance(schema, dict):
        raise UnsupportedSchema(f"not a schema: {schema!r}")
    if "$ref" in schema:
        ref = schema["$ref"]
        if not isinstance(ref, str) or not ref.startswith("#/$defs/") or ref[8:] not in defs:
            raise UnsupportedSchema(f"unresolvable $ref {ref!r}")
        _emit(defs[ref[8:]], defs, out)
        return
    for keyword in ("anyOf", "oneOf", "allOf", "not", "if", "items", "prefixItems"):
        if keyword in schema:
            raise UnsupportedSchema(f"{keyword} has no single layout")
    if "const" in schema or "enum" in schema:
        options = [schema["const"]] if "const" in schema else list(schema["enum"])
        _emit_choice(options, out)
        return
    kind = schema.get("type")
    if kind == "object":
        _emit_object(schema, defs, out)
    elif kind == "string":
        out.extend([Literal('"'), _string_value(schema), Literal('"')])
    elif kind in ("number", "integer"):
        out.append(Value(kind))
    elif kind == "boolean":
        out.append(Value("choice", options=("true", "false")))
    else:
        raise UnsupportedSchema(f"type {kind!r} is not supported")


def _emit_object(schema: dict[str, Any], defs: dict[str, Any], out: list[Segment]) -> None:
    properties = schema.get("properties", {})
    if schema.get("additionalProperties", True) is not False or "patternProperties" in schema:
        raise UnsupportedSchema("an object must have additionalProperties: false")
    if set(schema.get("required", ())) != set(properties):
        raise UnsupportedSchema("every property must be required")
    out.append(Literal("{"))
    for index, (name, sub_schema) in enumerate(properties.items()):
        out.append(Literal(("" if index == 0 else ",") + json.dumps(name) + ":"))
        _emit(sub_schema, defs, out)
    out.append(Literal("}"))


def _emit_choice(options: list[Any], out: list[Segment]) -> None:
    if not options:
        raise UnsupportedSchema("an empty enum")
    if all(isinstance(option, str) for option in options):
        texts = [json.dumps(option)[1:-1] for option in options]
        out.extend([Literal('"'), Value("choice", options=tuple(texts)), Literal('"')])
    elif not any(isinstance(option, str | dict | list) for option in options):
        out.append(Value("choice", options=tuple(json.dumps(option) for option in options)))
    else:
        raise UnsupportedSchema("an enum must hold only strings or only numbers, booleans and null")


def _string_value(schema: dict[str, Any]) -> Value:
    if "format" in schema or "minLength" in schema:
        raise UnsupportedSchema("string format and minLength are not supported")
    max_chars = schema.get("maxLength")
    char_class = None
    pattern = schema.get("pattern")
    if pattern is not None:
        match = _CLASS_PATTERN.match(pattern)
        if match is None:
            raise UnsupportedSchema(f"pattern {pattern!r} is not of the form ^[class]{{0,N}}$")
        char_class = match.group(1)
        if _char_run(char_class).fullmatch('"') or _char_run(char_class).fullmatch("\\"):
            raise UnsupportedSchema(f"pattern {pattern!r} admits a character that needs escaping")
        limit = int(match.group(2))
        max_chars = limit if max_chars is None else min(max_chars, limit)
    return Value("string", max_chars=max_chars, char_class=char_class)
