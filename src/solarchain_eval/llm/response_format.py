"""The structured-output request formats of the OpenAI-compatible APIs, derived from a pydantic model.

The JSON schema sent is the one the official SDK derives in strict mode (what its ``.parse()``
methods would send), so a local server and a hosted one see the same request.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel

from .errors import LLMConfigError

#: The characters a capped free-text field may hold: printable ASCII except ``"`` and ``\\``.
#: llama-cpp-python compiles a plain string (with or without ``maxLength``) to a grammar that
#: admits raw control characters, which no JSON parser accepts; a ``pattern`` takes precedence.
SCHEMA_TEXT_CHARS = r"[ !#-\[\]-~]"


def response_format(output_type: type[BaseModel], api: str) -> dict[str, Any]:
    """The strict JSON-schema response format the OpenAI SDK derives for ``output_type``.

    Parameters
    ----------
    output_type : a pydantic model class
        Its ``json_object_text_caps`` class attribute (field name -> ``maxLength``), if any, caps
        the free-text fields of the ``chat-json-object`` form.
    api : {"chat", "responses", "chat-json-object"}
        ``chat`` gives the ``response_format`` parameter of Chat Completions, ``responses`` the
        ``text.format`` parameter of the Responses API (what ``.parse()`` would send), and
        ``chat-json-object`` the ``{"type": "json_object", "schema": ...}`` form that
        llama-cpp-python's server turns into a grammar (it refuses ``json_schema``), with
        ``maxLength`` and a ``pattern`` on the free-text fields.
    """
    try:
        from openai.lib._parsing._completions import type_to_response_format_param
        from openai.lib._parsing._responses import type_to_text_format_param
    except ImportError as error:  # the helpers behind the SDK's .parse() methods
        raise LLMConfigError(
            f"the installed openai package lacks its structured-output helpers ({error}); install openai>=1.66"
        ) from None
    if api == "chat":
        return dict(type_to_response_format_param(output_type))
    if api == "responses":
        return dict(type_to_text_format_param(output_type))
    if api == "chat-json-object":
        schema = dict(type_to_response_format_param(output_type))["json_schema"]["schema"]
        caps = getattr(output_type, "json_object_text_caps", {})
        return {"type": "json_object", "schema": capped_schema(schema, caps)}
    raise LLMConfigError(f"unknown LLM API {api!r} (choose 'responses', 'chat' or 'chat-json-object')")


def capped_schema(schema: Any, caps: Mapping[str, int]) -> Any:
    """A copy of ``schema`` whose string fields named in ``caps`` have that ``maxLength`` and a
    ``pattern`` of :data:`SCHEMA_TEXT_CHARS` characters."""
    if isinstance(schema, list):
        return [capped_schema(item, caps) for item in schema]
    if not isinstance(schema, dict):
        return schema
    out = {key: capped_schema(value, caps) for key, value in schema.items()}
    properties = out.get("properties")
    if isinstance(properties, dict):
        for name, limit in caps.items():
            field_schema = properties.get(name)
            if isinstance(field_schema, dict) and field_schema.get("type") == "string":
                pattern = f"^{SCHEMA_TEXT_CHARS}{{0,{limit}}}$"
                properties[name] = {**field_schema, "maxLength": limit, "pattern": pattern}
    return out
