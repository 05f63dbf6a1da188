"""The data-only encoding an isolated agent's process answers in (:mod:`.isolated`).

What the agent's process sends back is read here, in the evaluating process, so it must not be
able to run code there: it is JSON (never a pickle) of a tagged tree of ``None``, ``bool``,
``int``, ``float`` (NaN and infinities included), ``str``, ``bytes``, ``list``, ``tuple``,
``dict`` and numpy numbers and arrays of boolean, integer or floating dtype. Values come back
with their exact type, dtype and bits, so the environment receives what it would have received
from the same agent in the evaluating process.

The hot path of an isolated agent, one array each way per step (the observation in, the action
out), travels as an *array frame* instead: a zero byte, the call's name, the array's dtype and
shape in ASCII, then its raw bytes. Reading one checks the dtype against the same numeric kinds
and the byte count against the shape; it is data, as the JSON is, only cheaper to write and read.
"""

from __future__ import annotations

import base64
import json
import math
import re
from typing import Any

import numpy as np

from ..common.errors import UserAgentError

#: Numpy dtypes an answer may carry: boolean, integer and floating, written as ``dtype.str``.
_DTYPE = re.compile(r"^[<>|=]?[biuf][1-9][0-9]?$")
_KINDS = "returns None, numbers, strings, bytes, lists, tuples, dicts with string keys and numeric numpy arrays"


class WireError(UserAgentError, ValueError):
    """A value that has no data-only encoding, or an answer that is not one."""


def _tree(value: Any) -> Any:
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int | float) and type(value) in (int, float):
        return value
    if isinstance(value, np.ndarray | np.generic):
        array = value if isinstance(value, np.ndarray) else np.asarray(value)
        if array.dtype.kind not in "biuf":
            raise WireError(f"a numpy value of dtype {array.dtype}: an isolated agent {_KINDS}")
        data = base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")
        if isinstance(value, np.generic):
            return {"s": [array.dtype.str, data]}
        return {"a": [array.dtype.str, list(array.shape), data]}
    if isinstance(value, bytes):
        return {"b": base64.b64encode(value).decode("ascii")}
    if type(value) is list:
        return [_tree(v) for v in value]
    if type(value) is tuple:
        return {"t": [_tree(v) for v in value]}
    if type(value) is dict:
        if not all(isinstance(k, str) for k in value):
            raise WireError(f"a dict with non-string keys: an isolated agent {_KINDS}")
        return {"d": [[k, _tree(v)] for k, v in value.items()]}
    raise WireError(f"a value of type {type(value).__name__}: an isolated agent {_KINDS}")


def encode(value: Any) -> bytes:
    """``value`` as data-only JSON bytes (raises :class:`WireError` for anything else)."""
    return json.dumps(_tree(value), separators=(",", ":")).encode("utf-8")


def _dtype(text: Any) -> np.dtype:
    if not isinstance(text, str) or not _DTYPE.match(text):
        raise WireError(f"not a numeric dtype: {text!r}")
    return np.dtype(text)


def _buffer(dtype: np.dtype, data: Any, count: int) -> np.ndarray:
    raw = base64.b64decode(str(data), validate=True)
    if len(raw) != count * dtype.itemsize:
        raise WireError(f"{len(raw)} bytes for {count} value(s) of {dtype}")
    return np.frombuffer(raw, dtype=dtype, count=count).copy()  # a writable array of its own


def _value(node: Any) -> Any:
    if node is None or isinstance(node, bool | int | float | str):
        return node
    if isinstance(node, list):
        return [_value(v) for v in node]
    if not isinstance(node, dict) or len(node) != 1:
        raise WireError("not an encoded value")
    ((tag, body),) = node.items()
    if tag == "t":
        return tuple(_value(v) for v in body)
    if tag == "d":
        return {str(k): _value(v) for k, v in body}
    if tag == "b":
        return base64.b64decode(str(body), validate=True)
    if tag == "s":
        dtype_text, data = body
        return _buffer(_dtype(dtype_text), data, 1)[0]
    if tag == "a":
        dtype_text, shape, data = body
        if not isinstance(shape, list) or not all(type(n) is int and n >= 0 for n in shape):
            raise WireError(f"not an array shape: {shape!r}")
        return _buffer(_dtype(dtype_text), data, math.prod(shape)).reshape(shape)
    raise WireError(f"unknown tag {tag!r}")


def decode(data: bytes) -> Any:
    """The value :func:`encode` wrote (raises :class:`WireError` for anything else)."""
    if data[:1] == FRAME:
        raise WireError("an array frame where an encoded value was expected")
    try:
        return _value(json.loads(data.decode("utf-8")))
    except WireError:
        raise
    except (ValueError, TypeError, RecursionError) as error:  # malformed JSON, tags or nesting
        raise WireError(f"a malformed answer ({type(error).__name__}: {error})") from None


#: The first byte of an array frame (JSON never starts with it).
FRAME = b"\x00"


def is_frame(data: bytes) -> bool:
    """Whether ``data`` is an array frame (:func:`pack_array`) rather than JSON or a pickle."""
    return data[:1] == FRAME


def frameable(value: Any) -> bool:
    """Whether ``value`` can travel as an array frame: a numpy array of boolean, integer or floating dtype."""
    return type(value) is np.ndarray and value.dtype.kind in "biuf"


def pack_array(label: str, array: np.ndarray) -> bytes:
    """``array`` (see :func:`frameable`) with a short ASCII ``label`` as one array frame."""
    shape = ",".join(str(n) for n in array.shape)
    head = f"{label}\x00{array.dtype.str}\x00{shape}\x00".encode("ascii")
    return FRAME + head + np.ascontiguousarray(array).tobytes()


def unpack_array(data: bytes) -> tuple[str, np.ndarray]:
    """The label and a writable copy of the array of a frame :func:`pack_array` wrote (else :class:`WireError`)."""
    parts = data[1:].split(b"\x00", 3)
    if not is_frame(data) or len(parts) != 4:
        raise WireError("not an array frame")
    label_raw, dtype_raw, shape_raw, raw = parts
    try:
        label, dtype_text, shape_text = (x.decode("ascii") for x in (label_raw, dtype_raw, shape_raw))
    except UnicodeDecodeError:
        raise WireError("an array frame with a header that is not ASCII") from None
    dtype = _dtype(dtype_text)
    if shape_text and not all(n.isdigit() and len(n) <= 12 for n in shape_text.split(",")):
        raise WireError(f"not an array shape: {shape_text!r}")
    shape = [int(n) for n in shape_text.split(",")] if shape_text else []
    count = math.prod(shape)
    if len(raw) != count * dtype.itemsize:
        raise WireError(f"{len(raw)} bytes for {count} value(s) of {dtype}")
    return label, np.frombuffer(raw, dtype=dtype, count=count).reshape(shape).copy()
