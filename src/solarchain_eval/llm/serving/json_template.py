"""A strict JSON schema as a template: the text it forces, and the values a model must choose.

A strict schema (every property required, in a fixed order, no alternatives) fixes every
character of a compact reply except its values: ``{"decision": "`` is the same in every Auditor
reply. :func:`compile_template` turns such a schema into a list of :class:`Literal` texts and
:class:`Value` slots; :mod:`.jump_forward` appends each literal to the model's context in one batch
and lets the model choose only the values, one token at a time, each checked by its slot's
:meth:`Value.accepts`. The replies are compact JSON ("," and ":" separators, no spaces).

Supported: objects (nested or by ``$ref`` into ``$defs``), strings (with ``enum``, ``maxLength``
and a ``pattern`` of the form ``^[class]{0,N}$``), numbers and integers (with ``minimum`` and
``maximum``: a bounded value is written without an exponent, and every prefix the model writes can
still end inside the bounds), booleans and ``enum``/``const`` of those. Anything else raises
:class:`UnsupportedSchema`, and the server answers that request with llama-cpp-python's
grammar-constrained sampling instead (whose grammar does not enforce numeric bounds).
"""

from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass
from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal
from typing import Any

from ...common.errors import InputDataError

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
#: Keywords of a number the template cannot enforce (the grammar path answers such schemas).
_UNSUPPORTED_NUMERIC = ("exclusiveMinimum", "exclusiveMaximum", "multipleOf")


@functools.cache
def _char_run(char_class: str) -> re.Pattern[str]:
    return re.compile(f"{char_class}*")


class UnsupportedSchema(InputDataError, ValueError):
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
    minimum, maximum : str or None
        A number's inclusive bounds, as decimal text (exact, unlike a float); a bounded number
        is written without an exponent.
    """

    kind: str
    max_chars: int | None = None
    char_class: str | None = None
    options: tuple[str, ...] = ()
    minimum: str | None = None
    maximum: str | None = None

    @property
    def bounded(self) -> bool:
        return self.minimum is not None or self.maximum is not None

    def accepts(self, text: str) -> bool:
        """Whether ``text`` can begin (or be) a value of this slot."""
        if self.kind in _NUMERIC:
            if _NUMERIC[self.kind][0].match(text) is None:
                return False
            return not self.bounded or self._reaches_bounds(text)
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
            if _NUMERIC[self.kind][1].match(text) is None:
                return False
            return not self.bounded or (self._reaches_bounds(text) and self._inside(Decimal(text)))
        if self.kind == "choice":
            return text in self.options
        return self.accepts(text)

    def _inside(self, value: Decimal) -> bool:
        return (self.minimum is None or value >= Decimal(self.minimum)) and (
            self.maximum is None or value <= Decimal(self.maximum)
        )

    def _reaches_bounds(self, text: str) -> bool:
        """Whether the number prefix ``text`` can still become a value inside the bounds."""
        return _reaches_bounds(self.kind, self.minimum, self.maximum, text)

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


@functools.lru_cache(maxsize=1 << 16)
def _reaches_bounds(kind: str, minimum: str | None, maximum: str | None, text: str) -> bool:
    # Cached: decoding asks this of every candidate token at every position, and the same
    # prefixes recur across the values and requests of a run.
    if "e" in text or "E" in text:
        return False  # bounded values are written without an exponent
    low = Decimal("-Infinity") if minimum is None else Decimal(minimum)
    high = Decimal("Infinity") if maximum is None else Decimal(maximum)
    if kind == "integer":  # the integers inside the bounds
        low = low if low.is_infinite() else low.to_integral_value(ROUND_CEILING)
        high = high if high.is_infinite() else high.to_integral_value(ROUND_FLOOR)
    if low > high:
        return False
    return any(a <= high and b >= low for a, b in reachable_values(text, integer=kind == "integer"))


def reachable_values(text: str, *, integer: bool) -> list[tuple[Decimal, Decimal]]:
    """Closed intervals holding every value a number written as ``text`` so far (a valid prefix
    without an exponent) can still become, within the digit limits of this module."""
    negative = text.startswith("-")
    body = text[1:] if negative else text
    step = Decimal(1) if integer else Decimal(10) ** -MAX_FRACTION_DIGITS  # the finest last digit
    largest = Decimal(10) ** MAX_INTEGER_DIGITS - step
    if not text:  # a sign may still come
        return [(-largest, largest)]
    if not body:
        spans = [(Decimal(0), largest)]
    elif "." in body:
        whole, fraction = body.split(".")
        value = Decimal(f"{whole}.{fraction}" if fraction else whole)
        room = Decimal(10) ** -len(fraction) - step if len(fraction) < MAX_FRACTION_DIGITS else Decimal(0)
        spans = [(value, value + room)]
    elif body == "0":  # no digit may follow a leading zero
        spans = [(Decimal(0), Decimal(0) if integer else Decimal(1) - step)]
    else:  # more integer digits (each one ten times the value), then a fraction
        start = Decimal(body)
        spans = [
            (start * 10**extra, (start + 1) * 10**extra - step) for extra in range(MAX_INTEGER_DIGITS - len(body) + 1)
        ]
    return [(-b, -a) for a, b in spans] if negative else spans


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
        out.append(_number_value(kind, schema))
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


def _bound_text(schema: dict[str, Any], keyword: str) -> str | None:
    bound = schema.get(keyword)
    if bound is None:
        return None
    if isinstance(bound, bool) or not isinstance(bound, int | float) or bound != bound or abs(bound) == float("inf"):
        raise UnsupportedSchema(f"{keyword} {bound!r} is not a finite number")
    # repr is the shortest text that reads back as the same float: the value a JSON parser sees.
    return str(bound) if isinstance(bound, int) else repr(float(bound))


def _number_value(kind: str, schema: dict[str, Any]) -> Value:
    unsupported = [keyword for keyword in _UNSUPPORTED_NUMERIC if keyword in schema]
    if unsupported:
        raise UnsupportedSchema(f"{', '.join(unsupported)} on a number is not supported")
    minimum, maximum = _bound_text(schema, "minimum"), _bound_text(schema, "maximum")
    if minimum is not None and maximum is not None and Decimal(minimum) > Decimal(maximum):
        raise UnsupportedSchema(f"minimum {minimum} is above maximum {maximum}")
    value = Value(kind, minimum=minimum, maximum=maximum)
    if value.bounded and not value.accepts(""):
        raise UnsupportedSchema(f"no {kind} of at most {MAX_INTEGER_DIGITS} digits lies inside the bounds")
    return value


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
