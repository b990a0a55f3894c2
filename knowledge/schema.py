"""Versioned JSON documents: one definition each, validation, JSON Schema, and a docs table.

Every JSON message on the bus and every JSON document the project writes (the navigation
graph's, the topological map's) is an object with ``"schema": "loci.<name>/<version>"``. A
:class:`MessageSchema` is written once, in a small vocabulary (:func:`string`,
:func:`number`, :func:`integer`, :func:`array`, :func:`obj`, :func:`mapping`), and gives:

* the validator used on receipt: required fields, types, ranges, choices and cross-field
  checks (such as "edges join existing nodes"). The schema is compiled to a msgspec type
  (:mod:`msgspec`, C speed: 1.6 µs for a ``loci.place/1`` against 99 µs for the walk of the
  spec, 61x, measured in one process); a message it refuses is walked again by the spec to
  say exactly what is wrong, so both must agree (a property test keeps them equal);
* the JSON Schema document that MCAP recordings carry, so Foxglove knows the fields;
* a row of the field table in the docs (:meth:`SchemaRegistry.markdown_table`).

What arrives is checked before it is parsed: its size (:data:`MAX_JSON_BYTES`, or the smaller
``max_bytes`` of the schema the receiver expects) and the nesting depth of its arrays and
objects (:data:`MAX_JSON_DEPTH`; a 2 kB payload of a thousand nested arrays once made the
parser raise ``RecursionError``, which stopped the agent). Any input at all gives a message
or :class:`ProtocolError`, never another exception.

Numbers must be finite (``NaN``/``Infinity`` are not JSON and are refused), integers are
not booleans, strings valid Unicode, and objects accept extra keys unless built with
``extra=False``. Decoded messages are plain dicts and lists, as JSON gives them. Encoding
writes compact UTF-8 JSON with msgspec (a non-finite number inside a free-form ``any`` field,
where no spec checks it, is written as ``null``).
"""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Annotated, Any, Literal

import msgspec
import numpy as np

from knowledge.errors import ProtocolError

_SCHEMA_ID = re.compile(r"(loci\.[a-z][a-z0-9_.]*)/([1-9][0-9]*)")
#: Largest JSON payload accepted on receipt, bytes (a schema may allow less: ``max_bytes``).
MAX_JSON_BYTES = 8 * 1024 * 1024
#: Deepest nesting of arrays and objects accepted on receipt (the project's messages nest 5 deep).
MAX_JSON_DEPTH = 32
#: ``max_bytes`` of the small messages people and tools send (intents, utterances, commands).
SMALL_MESSAGE_BYTES = 64 * 1024
# a JSON string, escapes included (unrolled loop: linear time on any input)
_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_OPEN = np.zeros(256, np.int8)
_OPEN[[ord("["), ord("{")]] = 1
_OPEN[[ord("]"), ord("}")]] = -1


def json_depth(payload: bytes) -> int:
    """The deepest nesting of arrays and objects in JSON text, found without parsing it.

    Brackets inside strings do not count. For text that is not JSON the result is an upper
    bound of what a parser would meet before failing. Linear time and memory in the payload.
    """
    opens = payload.count(b"[") + payload.count(b"{")
    if opens <= 1:
        return opens
    return _bracket_depth(_JSON_STRING.sub(b'""', payload) if b'"' in payload else payload)


def _bracket_depth(text: bytes) -> int:
    """The deepest nesting of brackets in ``text``, strings included: an upper bound of
    :func:`json_depth`, without its (slower) removal of strings."""
    steps = _OPEN[np.frombuffer(text, np.uint8)]
    steps = steps[steps != 0].astype(np.int32)
    return int(np.cumsum(steps).max()) if steps.size else 0


def within_depth(payload: bytes, limit: int) -> int | None:
    """None when ``payload`` nests at most ``limit`` deep, else its depth (:func:`json_depth`).
    Fast for the usual message: fewer brackets than the limit, or brackets (strings included)
    that never reach it, need no look at the strings."""
    if payload.count(b"[") + payload.count(b"{") <= limit or _bracket_depth(payload) <= limit:
        return None
    depth = json_depth(payload)
    return depth if depth > limit else None


@dataclass(frozen=True)
class Spec:
    """The constraints on one JSON value (build with the helper functions below)."""

    kind: str
    nullable: bool = False
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[Any, ...] | None = None
    max_length: int | None = None
    items: Spec | None = None
    min_items: int | None = None
    max_items: int | None = None
    required: Mapping[str, Spec] = field(default_factory=dict)
    optional: Mapping[str, Spec] = field(default_factory=dict)
    values: Spec | None = None
    extra: bool = True
    description: str = ""


def string(
    *,
    choices: Sequence[str] | None = None,
    max_length: int | None = None,
    nullable: bool = False,
    description: str = "",
) -> Spec:
    return Spec(
        "string",
        nullable=nullable,
        choices=tuple(choices) if choices else None,
        max_length=max_length,
        description=description,
    )


def number(
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    nullable: bool = False,
    description: str = "",
) -> Spec:
    return Spec("number", nullable=nullable, minimum=minimum, maximum=maximum, description=description)


def integer(
    *, minimum: int | None = None, maximum: int | None = None, nullable: bool = False, description: str = ""
) -> Spec:
    return Spec("integer", nullable=nullable, minimum=minimum, maximum=maximum, description=description)


def boolean(*, description: str = "") -> Spec:
    return Spec("boolean", description=description)


def array(
    items: Spec, *, min_items: int | None = None, max_items: int | None = None, description: str = ""
) -> Spec:
    return Spec("array", items=items, min_items=min_items, max_items=max_items, description=description)


def obj(
    required: Mapping[str, Spec] | None = None,
    optional: Mapping[str, Spec] | None = None,
    *,
    extra: bool = True,
    nullable: bool = False,
    description: str = "",
) -> Spec:
    """An object with named fields; ``extra=False`` refuses keys not listed."""
    return Spec(
        "object",
        required=dict(required or {}),
        optional=dict(optional or {}),
        extra=extra,
        nullable=nullable,
        description=description,
    )


def mapping(values: Spec, *, nullable: bool = False, description: str = "") -> Spec:
    """An object used as a map from any string key to values of one kind."""
    return Spec("object", values=values, nullable=nullable, description=description)


def _type_name(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def check_value(spec: Spec, value: Any, path: str) -> None:
    """Raise :class:`ProtocolError` naming where ``value`` (decoded JSON) breaks ``spec``
    (``path`` starts the place names, e.g. ``"args"``)."""
    _check(spec, value, path)


def _check(spec: Spec, value: Any, path: str) -> None:
    if value is None:
        if spec.nullable:
            return
        raise ProtocolError(f"{path}: must not be null")
    kind = spec.kind
    if kind == "string":
        if not isinstance(value, str):
            raise ProtocolError(f"{path}: expected a string, got {_type_name(value)}")
        if spec.max_length is not None and len(value) > spec.max_length:
            raise ProtocolError(f"{path}: longer than {spec.max_length} characters")
        if not value.isascii():
            try:
                value.encode("utf-8")
            except UnicodeEncodeError as exc:  # a lone surrogate ("\ud800"): not text
                raise ProtocolError(f"{path}: not valid Unicode text ({exc.reason})") from None
    elif kind in ("number", "integer"):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ProtocolError(
                f"{path}: expected {'an integer' if kind == 'integer' else 'a number'}, got {_type_name(value)}"
            )
        if kind == "integer" and not isinstance(value, int):
            raise ProtocolError(f"{path}: expected an integer, got {value!r}")
        if not math.isfinite(value):
            raise ProtocolError(f"{path}: must be finite, got {value!r}")
        if spec.minimum is not None and value < spec.minimum:
            raise ProtocolError(f"{path}: {value!r} is below the minimum {spec.minimum:g}")
        if spec.maximum is not None and value > spec.maximum:
            raise ProtocolError(f"{path}: {value!r} is above the maximum {spec.maximum:g}")
    elif kind == "boolean":
        if not isinstance(value, bool):
            raise ProtocolError(f"{path}: expected a boolean, got {_type_name(value)}")
    elif kind == "array":
        if not isinstance(value, list):
            raise ProtocolError(f"{path}: expected an array, got {_type_name(value)}")
        if spec.min_items is not None and len(value) < spec.min_items:
            raise ProtocolError(f"{path}: needs at least {spec.min_items} items, has {len(value)}")
        if spec.max_items is not None and len(value) > spec.max_items:
            raise ProtocolError(f"{path}: allows at most {spec.max_items} items, has {len(value)}")
        assert spec.items is not None
        for i, item in enumerate(value):
            _check(spec.items, item, f"{path}[{i}]")
    elif kind == "object":
        if not isinstance(value, dict):
            raise ProtocolError(f"{path}: expected an object, got {_type_name(value)}")
        if spec.values is not None:
            for k, v in value.items():
                _check(spec.values, v, f"{path}.{k}")
        else:
            for k, sub in spec.required.items():
                if k not in value:
                    raise ProtocolError(f"{path}: missing required field {k!r}")
                _check(sub, value[k], f"{path}.{k}")
            for k, sub in spec.optional.items():
                if k in value:
                    _check(sub, value[k], f"{path}.{k}")
            if not spec.extra:
                unknown = sorted(set(value) - set(spec.required) - set(spec.optional))
                if unknown:
                    raise ProtocolError(f"{path}: unknown field {unknown[0]!r}")
    elif kind != "any":
        raise ValueError(f"unknown spec kind {kind!r}")
    if spec.choices is not None and value not in spec.choices:
        raise ProtocolError(f"{path}: {value!r} is not one of {', '.join(map(str, spec.choices))}")


def _json_schema(spec: Spec) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if spec.kind != "any":
        out["type"] = [spec.kind, "null"] if spec.nullable else spec.kind
    if spec.description:
        out["description"] = spec.description
    if spec.minimum is not None:
        out["minimum"] = spec.minimum
    if spec.maximum is not None:
        out["maximum"] = spec.maximum
    if spec.choices is not None:
        out["enum"] = list(spec.choices) + ([None] if spec.nullable else [])
    if spec.max_length is not None:
        out["maxLength"] = spec.max_length
    if spec.kind == "array":
        assert spec.items is not None
        out["items"] = _json_schema(spec.items)
        if spec.min_items is not None:
            out["minItems"] = spec.min_items
        if spec.max_items is not None:
            out["maxItems"] = spec.max_items
    if spec.kind == "object":
        if spec.values is not None:
            out["additionalProperties"] = _json_schema(spec.values)
        else:
            props = {**spec.required, **spec.optional}
            out["properties"] = {k: _json_schema(v) for k, v in props.items()}
            out["required"] = list(spec.required)
            out["additionalProperties"] = spec.extra
    return out


_FLOAT_MAX = sys.float_info.max


def _msgspec_type(spec: Spec, name: str) -> Any:
    """The msgspec type that accepts what :func:`_check` accepts (``name`` names the structs).

    It may refuse more (an integer beyond 64 bits): a refusal is explained by :func:`_check`,
    and a value :func:`_check` then accepts is accepted; it must never accept more (a
    property test in the tests checks that on random and mutated messages)."""
    k = spec.kind
    t: Any
    if k == "any":  # any JSON value; null only when nullable
        return Any if spec.nullable else bool | int | float | str | list[Any] | dict[str, Any]
    if k == "string":
        if spec.choices:
            t = Literal[tuple(spec.choices)]
        elif spec.max_length is not None:
            t = Annotated[str, msgspec.Meta(max_length=spec.max_length)]
        else:
            t = str
    elif k == "number":
        lo = -_FLOAT_MAX if spec.minimum is None else max(spec.minimum, -_FLOAT_MAX)
        hi = _FLOAT_MAX if spec.maximum is None else min(spec.maximum, _FLOAT_MAX)
        t = Annotated[float, msgspec.Meta(ge=lo, le=hi)]
    elif k == "integer":
        ge = None if spec.minimum is None else int(spec.minimum)
        le = None if spec.maximum is None else int(spec.maximum)
        t = Annotated[int, msgspec.Meta(ge=ge, le=le)]
    elif k == "boolean":
        t = bool
    elif k == "array":
        assert spec.items is not None
        item = _msgspec_type(spec.items, name + "_item")
        sizes = msgspec.Meta(min_length=spec.min_items, max_length=spec.max_items)
        t = Annotated[list[item], sizes]  # type: ignore[valid-type]
    elif k == "object" and spec.values is not None:
        t = dict[str, _msgspec_type(spec.values, name + "_value")]  # type: ignore[misc]
    elif k == "object":
        t = _struct(spec, name)
    else:
        raise ValueError(f"unknown spec kind {k!r}")
    if spec.choices is not None and k != "string":
        raise ValueError(f"{name}: choices are supported on strings only")
    return t | None if spec.nullable else t


def _struct(spec: Spec, name: str, head: Sequence[tuple[str, Any]] = ()) -> Any:
    """A msgspec Struct type for an :func:`obj` spec (fields renamed, so any JSON key works)."""
    fields: list[tuple[str, Any] | tuple[str, Any, Any]] = []
    rename: dict[str, str] = {}
    for i, (key, typ) in enumerate(head):
        fields.append((f"h{i}", typ))
        rename[f"h{i}"] = key
    for i, (key, sub) in enumerate(spec.required.items()):
        fields.append((f"r{i}", _msgspec_type(sub, f"{name}_{i}")))
        rename[f"r{i}"] = key
    for i, (key, sub) in enumerate(spec.optional.items()):
        fields.append((f"o{i}", _msgspec_type(sub, f"{name}_o{i}") | msgspec.UnsetType, msgspec.UNSET))
        rename[f"o{i}"] = key
    return msgspec.defstruct(
        re.sub(r"\W", "_", name), fields, kw_only=True, rename=rename, forbid_unknown_fields=not spec.extra
    )


@dataclass(frozen=True)
class MessageSchema:
    """A versioned JSON message: ``{"schema": "<name>/<version>", ...body fields}``.

    Attributes:
        name: ``loci.<name>`` (lower case).
        version: a positive integer, bumped on incompatible changes.
        body: an :func:`obj` spec of the fields besides ``"schema"``.
        checks: functions of the whole (type-checked) message returning a reason string
            when something across fields is wrong (e.g. an edge to a missing node), else None.
        description: one line for the docs and the JSON Schema.
        max_bytes: the largest payload of this message accepted on receipt.
    """

    name: str
    version: int
    body: Spec
    checks: tuple[Callable[[dict[str, Any]], str | None], ...] = ()
    description: str = ""
    max_bytes: int = MAX_JSON_BYTES

    def __post_init__(self) -> None:
        if not _SCHEMA_ID.fullmatch(f"{self.name}/{self.version}"):
            raise ValueError(f"schema {self.name!r}/{self.version!r} must look like 'loci.place'/1")
        if self.body.kind != "object" or self.body.values is not None:
            raise ValueError("a message body must be an obj() spec with named fields")

    @property
    def id(self) -> str:
        """``"<name>/<version>"``, the value of the message's ``"schema"`` field."""
        return f"{self.name}/{self.version}"

    @cached_property
    def compiled(self) -> Any:
        """The msgspec type of the whole message (``schema`` and the body), built on first use."""
        return _struct(self.body, self.id, head=(("schema", Literal[self.id]),))

    def validate(self, message: Any) -> None:
        """Raise :class:`ProtocolError` naming the first problem, else return."""
        if not isinstance(message, dict):
            raise ProtocolError(f"{self.id}: a message must be a JSON object, got {_type_name(message)}")
        if message.get("schema") != self.id:
            raise ProtocolError(f"{self.id}: 'schema' is {message.get('schema')!r}, expected {self.id!r}")
        try:
            msgspec.convert(message, type=self.compiled)
        except msgspec.ValidationError:
            _check(self.body, message, self.id)  # says what is wrong (or, at an edge, accepts)
        for check in self.checks:
            reason = check(message)
            if reason:
                raise ProtocolError(f"{self.id}: {reason}")

    def json_schema(self) -> dict[str, Any]:
        """The JSON Schema (draft 2020-12) document of the message, for MCAP and tools."""
        doc = _json_schema(self.body)
        doc["properties"] = {"schema": {"const": self.id}, **doc["properties"]}
        doc["required"] = ["schema", *doc["required"]]
        return {
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": self.id,
            "title": self.id,
            **({"description": self.description} if self.description else {}),
            **doc,
        }


class SchemaRegistry:
    """The known :class:`MessageSchema` s by id; decodes and validates JSON payloads."""

    def __init__(self, schemas: Sequence[MessageSchema] = ()) -> None:
        self._schemas: dict[str, MessageSchema] = {}
        for s in schemas:
            self.register(s)

    def register(self, schema: MessageSchema) -> MessageSchema:
        """Add a schema; registering a different schema under a known id is an error."""
        known = self._schemas.get(schema.id)
        if known is not None and known is not schema:
            raise ValueError(f"schema {schema.id} is already registered; bump the version for a change")
        self._schemas[schema.id] = schema
        return schema

    def __contains__(self, schema_id: object) -> bool:
        return schema_id in self._schemas

    def get(self, schema_id: str) -> MessageSchema:
        try:
            return self._schemas[schema_id]
        except KeyError:
            raise ProtocolError(
                f"unknown message schema {schema_id!r} (known: {', '.join(sorted(self._schemas))})"
            ) from None

    def ids(self) -> list[str]:
        return sorted(self._schemas)

    def markdown_table(self) -> str:
        """Every schema's fields as a Markdown table (docs/bus.md shows it; a test keeps the
        two equal, so the docs say what the code checks): required fields, then *optional*
        ones, each with its type in short."""
        rows = ["| schema | fields (required; *optional*) | what |", "| --- | --- | --- |"]
        for sid in self.ids():
            sch = self._schemas[sid]
            rows.append(f"| `{sid}` | {_fields(sch.body)} | {sch.description} |")
        return "\n".join(rows)

    def validate(self, message: Any, expected: str | None = None) -> MessageSchema:
        """Check a decoded message; ``expected`` (a schema id) refuses any other schema."""
        if not isinstance(message, dict):
            raise ProtocolError(f"a message must be a JSON object, got {_type_name(message)}")
        sid = message.get("schema")
        if not isinstance(sid, str):
            raise ProtocolError("a message needs a 'schema' string such as 'loci.place/1'")
        if expected is not None and sid != expected:
            raise ProtocolError(f"expected a {expected} message, got {sid!r}")
        schema = self.get(sid)
        schema.validate(message)
        return schema

    def decode(self, payload: bytes, expected: str | None = None) -> dict[str, Any]:
        """Parse and validate a JSON payload; :class:`ProtocolError` says what is wrong.

        The size (``expected``'s ``max_bytes``, else :data:`MAX_JSON_BYTES`) and the nesting
        depth (:data:`MAX_JSON_DEPTH`) are checked before parsing; no input raises anything
        but :class:`ProtocolError`.
        """
        limit = self.get(expected).max_bytes if expected is not None else MAX_JSON_BYTES
        if not isinstance(payload, bytes | bytearray | memoryview):
            raise ProtocolError(f"a JSON payload must be bytes, got {type(payload).__name__}")
        payload = bytes(payload)
        if len(payload) > limit:
            what = expected or "JSON"
            raise ProtocolError(f"{what} payload of {len(payload)} bytes exceeds {limit}")
        depth = within_depth(payload, MAX_JSON_DEPTH)
        if depth is not None:
            raise ProtocolError(f"JSON nested {depth} deep; at most {MAX_JSON_DEPTH} levels are accepted")
        try:
            message = msgspec.json.decode(payload)
        except (msgspec.DecodeError, ValueError, RecursionError) as exc:  # bad UTF-8, 1e400, ...
            raise ProtocolError(f"not valid JSON: {_json_error(payload, exc)}") from exc
        schema = self.validate(message, expected)
        if len(payload) > schema.max_bytes:
            raise ProtocolError(f"{schema.id} payload of {len(payload)} bytes exceeds {schema.max_bytes}")
        assert isinstance(message, dict)
        return message

    def encode(self, message: Mapping[str, Any], expected: str | None = None) -> bytes:
        """Validate and serialise a message (compact UTF-8 JSON)."""
        doc = dict(message)
        self.validate(doc, expected)
        try:
            return msgspec.json.encode(doc)
        except (TypeError, ValueError, msgspec.EncodeError) as exc:  # an object inside an "any" field
            raise ProtocolError(f"{doc.get('schema')}: cannot be written as JSON: {exc}") from exc


def _json_error(payload: bytes, exc: Exception) -> str:
    """What is wrong with text that is not JSON, in the standard library's words (line and
    column, "NaN is not a JSON number"); msgspec's own message when that parser has none."""
    try:
        json.loads(payload, parse_constant=_refuse_constant)
    except ProtocolError as inner:
        return str(inner)
    except (ValueError, RecursionError) as inner:
        return str(inner)
    return str(exc)


def _refuse_constant(name: str) -> Any:
    raise ProtocolError(f"{name} is not a JSON number")


def _short(spec: Spec, depth: int = 0) -> str:
    """A spec's type in a few characters: ``int ≥ 0``, ``[{...}]``, ``room|corridor``."""
    k = spec.kind
    if k == "object":
        if spec.values is not None:
            text = "{key: " + _short(spec.values, depth + 1) + "}"
        elif depth >= 1 or not (spec.required or spec.optional):
            names = [f"`{n}`" for n in spec.required] + [f"*`{n}`*" for n in spec.optional]
            text = "{" + ", ".join(names) + "}"
        else:
            text = "{" + _fields(spec, depth + 1) + "}"
    elif k == "array":
        text = "[" + (_short(spec.items, depth + 1) if spec.items is not None else "") + "]"
    elif spec.choices:
        text = " / ".join(str(c) for c in spec.choices)
    else:
        text = {"number": "num", "integer": "int", "string": "str", "boolean": "bool"}.get(k, k)
        if spec.minimum is not None and spec.maximum is not None:
            text += f" {spec.minimum:g}..{spec.maximum:g}"
        elif spec.minimum is not None:
            text += f" ≥ {spec.minimum:g}"
    return text + (" or null" if spec.nullable else "")


def _fields(spec: Spec, depth: int = 0) -> str:
    req = [f"`{n}` {_short(v, depth)}" for n, v in spec.required.items()]
    opt = [f"*`{n}`* {_short(v, depth)}" for n, v in spec.optional.items()]
    return "; ".join(p for p in (", ".join(req), ", ".join(opt)) if p)
