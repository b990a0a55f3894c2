"""Versioned JSON messages: their schemas, validation on receipt, and JSON Schema for MCAP.

Every JSON payload on the bus is an object with ``"schema": "loci.<name>/<version>"``. A
:class:`MessageSchema` is written once, in a small vocabulary (:func:`string`,
:func:`number`, :func:`integer`, :func:`array`, :func:`obj`, ...), and gives both the
validator used on receipt (required fields, types, ranges, choices, and cross-field checks
such as "edges join existing nodes") and the JSON Schema document that MCAP recordings carry
so Foxglove knows the fields. :data:`SCHEMAS` holds the project's schemas; other modules may
:meth:`SchemaRegistry.register` more.

Numbers must be finite (``NaN``/``Infinity`` are not JSON and are refused), integers are
not booleans, and objects accept extra keys unless built with ``extra=False``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from knowledge.errors import ProtocolError

_SCHEMA_ID = re.compile(r"(loci\.[a-z][a-z0-9_.]*)/([1-9][0-9]*)")
#: Largest JSON payload accepted on receipt, bytes.
MAX_JSON_BYTES = 8 * 1024 * 1024


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
    """

    name: str
    version: int
    body: Spec
    checks: tuple[Callable[[dict[str, Any]], str | None], ...] = ()
    description: str = ""

    def __post_init__(self) -> None:
        if not _SCHEMA_ID.fullmatch(f"{self.name}/{self.version}"):
            raise ValueError(f"schema {self.name!r}/{self.version!r} must look like 'loci.place'/1")
        if self.body.kind != "object" or self.body.values is not None:
            raise ValueError("a message body must be an obj() spec with named fields")

    @property
    def id(self) -> str:
        """``"<name>/<version>"``, the value of the message's ``"schema"`` field."""
        return f"{self.name}/{self.version}"

    def validate(self, message: Any) -> None:
        """Raise :class:`ProtocolError` naming the first problem, else return."""
        if not isinstance(message, dict):
            raise ProtocolError(f"{self.id}: a message must be a JSON object, got {_type_name(message)}")
        if message.get("schema") != self.id:
            raise ProtocolError(f"{self.id}: 'schema' is {message.get('schema')!r}, expected {self.id!r}")
        _check(self.body, message, self.id)
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
        """Parse and validate a JSON payload; :class:`ProtocolError` says what is wrong."""
        if len(payload) > MAX_JSON_BYTES:
            raise ProtocolError(f"JSON payload of {len(payload)} bytes exceeds {MAX_JSON_BYTES}")
        try:
            message = json.loads(payload, parse_constant=_refuse_constant)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ProtocolError(f"not valid JSON: {exc}") from exc
        self.validate(message, expected)
        assert isinstance(message, dict)
        return message

    def encode(self, message: Mapping[str, Any], expected: str | None = None) -> bytes:
        """Validate and serialise a message (compact UTF-8 JSON)."""
        doc = dict(message)
        self.validate(doc, expected)
        try:
            return json.dumps(doc, allow_nan=False, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
        except (TypeError, ValueError) as exc:
            raise ProtocolError(f"{doc.get('schema')}: cannot be written as JSON: {exc}") from exc


def _refuse_constant(name: str) -> Any:
    raise ProtocolError(f"not valid JSON: {name} is not a JSON number")


# ---- the project's messages -------------------------------------------------------------

_STAMP = number(minimum=0, description="seconds since the Unix epoch")
_PROBABILITY = number(minimum=0, maximum=1)
_CLASS = string(max_length=64, description="place class: room, corridor, doorway, hallway, ...")
_NODE_ID = integer(minimum=0)


def _graph_checks(message: dict[str, Any]) -> str | None:
    ids = [n["id"] for n in message["nodes"]]
    known = set(ids)
    if len(known) != len(ids):
        return "nodes: node ids must be unique"
    for i, (a, b) in enumerate(message["edges"]):
        if a not in known or b not in known:
            return f"edges[{i}]: [{a}, {b}] names a node that is not in 'nodes'"
    return None


def _area_checks(message: dict[str, Any]) -> str | None:
    ids = [a["id"] for a in message["areas"]]
    if len(set(ids)) != len(ids):
        return "areas: area ids must be unique"
    return None


PLACE = MessageSchema(
    "loci.place",
    1,
    obj(
        {
            "stamp": _STAMP,
            "label": _CLASS,
            "probabilities": mapping(_PROBABILITY, description="class → probability"),
        },
        {
            "node": integer(minimum=0, nullable=True, description="the navigation node the robot is at"),
            "coverage": number(
                minimum=0,
                maximum=1,
                description="share of the 360° scan's beams measured or hit in the local map "
                "(the rest interpolated); below the graph's min_coverage the label does not vote",
            ),
            "raw_probabilities": mapping(
                _PROBABILITY, description="class → probability: the classifier's histogram of this scan"
            ),
            "filtered_probabilities": mapping(
                _PROBABILITY,
                nullable=True,
                description="class → probability: the trajectory HMM's belief after this scan (null: no HMM)",
            ),
        },
    ),
    description="the place the robot is in now: the class that votes for navigation nodes and its "
    "probabilities (the HMM's belief, or the classifier's histogram), and both histograms",
)

GRAPH = MessageSchema(
    "loci.graph",
    1,
    obj(
        {
            "stamp": _STAMP,
            "nodes": array(
                obj(
                    {
                        "id": _NODE_ID,
                        "x": number(description="metres, odometry frame"),
                        "y": number(description="metres, odometry frame"),
                        "kind": string(choices=("place", "doorway")),
                        "label": string(max_length=64, nullable=True, description="majority class"),
                    },
                    {
                        "width": number(minimum=0, nullable=True, description="doorway width, metres"),
                        "orientation": number(nullable=True, description="doorway normal, radians"),
                    },
                )
            ),
            "edges": array(array(_NODE_ID, min_items=2, max_items=2)),
        },
        {"frame_id": string(max_length=64)},
    ),
    checks=(_graph_checks,),
    description="the navigation graph: nodes dropped along the robot's path, edges between them",
)

AREAS = MessageSchema(
    "loci.areas",
    1,
    obj(
        {
            "stamp": _STAMP,
            "areas": array(
                obj(
                    {
                        "id": integer(minimum=0),
                        "label": string(max_length=64, nullable=True),
                        "nodes": array(_NODE_ID, min_items=1),
                    }
                )
            ),
        }
    ),
    checks=(_area_checks,),
    description="topological areas: connected place nodes, split at doorways, with their class",
)

_COUNTERS = obj(
    {
        "received": integer(minimum=0),
        "delivered": integer(minimum=0),
        "dropped": integer(minimum=0),
        "invalid": integer(minimum=0),
    },
    {"published": integer(minimum=0), "queued": integer(minimum=0)},
)

DIAGNOSTICS = MessageSchema(
    "loci.diagnostics",
    1,
    obj(
        {"stamp": _STAMP, "robot": string(max_length=63), "streams": mapping(_COUNTERS)},
        {"uptime": number(minimum=0, description="seconds"), "extra": mapping(Spec("any"))},
    ),
    description="per-stream counters of the bus: received, delivered, dropped, invalid",
)

ERROR = MessageSchema(
    "loci.error",
    1,
    obj({"reason": string()}, {"key": string(), "stamp": _STAMP}),
    description="an error answer to a query or request",
)

# ---- the dialogue (agent/dialogue_agent.py, agent/dialogue/, docs/dialogue.md) ----------------

#: What a ``loci.intent/1`` can ask of the agent, and the ``args`` each kind takes.
INTENT_KINDS = (
    "assert_type",
    "assert_name",
    "assert_object",
    "ask_place",
    "ask_where",
    "follow_me",
    "look_around",
    "go_to",
    "stop",
    "answer",
)
#: ``loci.say/1`` statuses: the answer or the command's outcome, a long command started, a refusal.
SAY_STATUSES = ("ok", "accepted", "error")
_ID = string(max_length=128, description="an identifier chosen by the sender (unique per sender)")
_WORDS = string(max_length=200)
_SPEAKER = string(max_length=128, description="who speaks (a person's name, or 'tutor')")
#: A noun phrase naming what an intent is about: "the television", "a room with a couch".
TARGET = obj(
    {"head": _WORDS},
    {
        "determiner": string(choices=("the", "a"), nullable=True),
        "with": array(_WORDS, max_items=8, description="objects the referent has: 'a room with a couch'"),
        "text": string(max_length=400, description="the phrase as said"),
    },
    extra=False,
    description="a referring expression: head noun ('television', 'kitchen', 'room') and its objects",
)
_NONE = obj({}, extra=False)
#: ``args`` of each intent kind.
INTENT_ARGS: dict[str, Spec] = {
    "assert_type": obj({"type": _WORDS}, extra=False, description="'You are in the corridor'"),
    "assert_name": obj({"name": _WORDS}, extra=False, description="'I call it the recreation room'"),
    "assert_object": obj({"object": _WORDS}, extra=False, description="'This is the charging station'"),
    "ask_place": _NONE,
    "ask_where": obj({"target": TARGET}, extra=False),
    "follow_me": _NONE,
    "look_around": _NONE,
    "go_to": obj({"target": TARGET}, extra=False),
    "stop": _NONE,
    "answer": obj(
        {"answer": string(max_length=400, description="'yes', 'no', or a choice the question offered")},
        {
            "question": string(
                max_length=128, nullable=True, description="the loci.ask/1 id (none: the latest)"
            )
        },
        extra=False,
    ),
}


def _intent_checks(message: dict[str, Any]) -> str | None:
    kind = message["intent"]
    try:
        _check(INTENT_ARGS[kind], message.get("args", {}), "args")
    except ProtocolError as exc:
        return f"{kind}: {exc}"
    return None


UTTERANCE = MessageSchema(
    "loci.utterance",
    1,
    obj(
        {"text": string(max_length=10_000)},
        {
            "stamp": _STAMP,
            "speaker": _SPEAKER,
            "id": _ID,
            "source": string(max_length=128, description="the recogniser or 'console'"),
        },
    ),
    description="something a person said (a speech recogniser's or a console's text)",
)

INTENT = MessageSchema(
    "loci.intent",
    1,
    obj(
        {"id": _ID, "speaker": _SPEAKER, "intent": string(choices=INTENT_KINDS)},
        {
            "args": mapping(Spec("any"), description="the kind's arguments (see INTENT_ARGS)"),
            "stamp": _STAMP,
            "text": string(max_length=10_000, description="the utterance it was understood from"),
        },
    ),
    checks=(_intent_checks,),
    description="a structured request to the agent; every intent gets exactly one reply",
)

SAY = MessageSchema(
    "loci.say",
    1,
    obj(
        {"text": string(max_length=10_000)},
        {
            "stamp": _STAMP,
            "in_reply_to": string(max_length=128, nullable=True, description="the intent this replies to"),
            "status": string(choices=SAY_STATUSES, description="default ok"),
            "reason": string(max_length=2000, nullable=True, description="why an intent was refused"),
            "task": string(
                max_length=128, nullable=True, description="the intent whose task this reports on"
            ),
            "intent": string(max_length=64, nullable=True, description="the kind of the intent replied to"),
            "to": string(max_length=128, nullable=True, description="the speaker addressed"),
            "content": mapping(
                Spec("any", nullable=True), description="the answer as data (area, objects, node, path)"
            ),
        },
    ),
    description="what the robot says: a reply to an intent, a report on a task, or a remark",
)

ASK = MessageSchema(
    "loci.ask",
    1,
    obj(
        {
            "id": _ID,
            "text": string(max_length=10_000),
            "choices": array(_WORDS, min_items=1, max_items=16, description="the answers expected"),
        },
        {
            "stamp": _STAMP,
            "in_reply_to": string(max_length=128, nullable=True, description="the intent this replies to"),
            "about": mapping(
                Spec("any", nullable=True), description="what is unclear, e.g. {kind: false_doorway, node: 7}"
            ),
            "to": string(max_length=128, nullable=True, description="the speaker addressed"),
        },
    ),
    description="a question the robot asks; answered by a loci.intent/1 'answer' naming its id",
)

#: The registry of the project's JSON messages.
SCHEMAS = SchemaRegistry([PLACE, GRAPH, AREAS, DIAGNOSTICS, ERROR, UTTERANCE, INTENT, SAY, ASK])


# ---- the (simulated) base: commands, status, ground truth --------------------------------

_POSE = {
    "x": number(description="metres"),
    "y": number(description="metres"),
    "theta": number(description="heading, radians, counter-clockwise"),
}
_WAYPOINT = obj(
    {"x": number(description="metres"), "y": number(description="metres")},
    {"theta": number(nullable=True, description="heading there, radians (the last point's: the goal's)")},
)
#: What a base can report it is doing (``loci.base_status/1``).
BASE_STATUSES = ("idle", "velocity", "route", "active", "reached", "collided", "failed", "cancelled")


def _goal_checks(message: dict[str, Any]) -> str | None:
    if message.get("cancel"):
        return None
    if (message.get("goal") is not None) == bool(message.get("path")):
        return "give either 'goal' (a pose) or 'path' (waypoints), or 'cancel': true"
    return None


TWIST = MessageSchema(
    "loci.twist",
    1,
    obj(
        {
            "v": number(minimum=-10, maximum=10, description="forward speed, m/s"),
            "omega": number(minimum=-20, maximum=20, description="turn rate, rad/s, counter-clockwise"),
        },
        {"stamp": _STAMP},
    ),
    description="a velocity command for the base (it stops when commands stop coming)",
)

BASE_GOAL = MessageSchema(
    "loci.base_goal",
    1,
    obj(
        {},
        {
            "id": string(max_length=128, description="names the goal in status reports; repeats are ignored"),
            "stamp": _STAMP,
            "frame_id": string(choices=("odom", "map"), description="frame of the points (default odom)"),
            "goal": _WAYPOINT,
            "path": array(_WAYPOINT, min_items=1, max_items=10_000),
            "plan": boolean(description="plan around obstacles (default true); false: straight lines"),
            "cancel": boolean(description="stop whatever the base is doing"),
        },
    ),
    checks=(_goal_checks,),
    description="where the base should go: a pose, or a path of waypoints ending at the goal",
)

BASE_STATUS = MessageSchema(
    "loci.base_status",
    1,
    obj(
        {"stamp": _STAMP, "status": string(choices=BASE_STATUSES)},
        {
            "goal": string(
                max_length=128, nullable=True, description="the goal's id ('route': a scripted route)"
            ),
            "reason": string(max_length=2000, nullable=True),
            "pose": obj(_POSE, description="odometry pose (frame odom)"),
            "distance": number(minimum=0, description="metres driven so far"),
        },
    ),
    description="what the base does: a goal became active, was reached, failed, or the base collided",
)

TRUTH = MessageSchema(
    "loci.truth",
    1,
    obj(
        {"stamp": _STAMP, **_POSE},
        {
            "frame_id": string(max_length=64),
            "odom": obj(_POSE, description="the odometry pose at the same instant"),
            "space": integer(minimum=0, description="the building's space id there (0: none)"),
            "label": string(max_length=64, nullable=True, description="the place class there"),
            "collisions": integer(minimum=0),
        },
    ),
    description="the simulated robot's true pose (frame map) and place class, for evaluation only",
)

for _schema in (TWIST, BASE_GOAL, BASE_STATUS, TRUTH):
    SCHEMAS.register(_schema)


# ---- people, objects, concepts (the conceptual map) ------------------------------------------

_XY = array(number(), min_items=2, max_items=2, description="[x, y] metres")

PEOPLE = MessageSchema(
    "loci.people",
    1,
    obj(
        {
            "stamp": _STAMP,
            "legs": array(_XY, description="leg centroids, tracking frame"),
            "people": array(obj({"x": number(), "y": number(), "legs": integer(minimum=0, maximum=2)})),
            "tracks": array(
                obj(
                    {"id": integer(minimum=0), "x": number(), "y": number()},
                    {
                        "vx": number(description="m/s"),
                        "vy": number(description="m/s"),
                        "misses": integer(minimum=0),
                        "age": integer(minimum=0),
                    },
                )
            ),
        },
        {"frame_id": string(max_length=64, description="the tracking frame (odom, or the laser's)")},
    ),
    description="people in one laser scan: legs, persons (leg pairs) and confirmed tracks",
)

_AREA_ID = integer(minimum=0)
_OBJECT_REF = obj({"name": _WORDS}, {"kind": string(max_length=200, nullable=True)})

OBJECTS = MessageSchema(
    "loci.objects",
    1,
    obj(
        {
            "stamp": _STAMP,
            "recognitions": array(
                obj(
                    {"name": _WORDS, "kind": string(max_length=200, nullable=True), "score": number()},
                    {
                        "node": integer(minimum=0, nullable=True, description="the node it was seen from"),
                        "area": integer(minimum=0, nullable=True, description="the area it was seen from"),
                        "inliers": integer(minimum=0),
                        "bearing": number(nullable=True, description="radians, left of the camera axis"),
                    },
                )
            ),
        },
        {"frame_id": string(max_length=64)},
    ),
    description="the object instances the camera recognised in one frame",
)


def _concepts_checks(message: dict[str, Any]) -> str | None:
    for key, area in message["areas"].items():
        if not isinstance(area, dict):
            return f"areas.{key}: expected an object"
        if "id" in area and str(area["id"]) != str(key):
            return f"areas.{key}: its 'id' is {area['id']!r}"
    return None


CONCEPT_AREA = obj(
    {},
    {
        "id": _AREA_ID,
        "class": string(max_length=64, nullable=True, description="room, corridor, hallway (or None)"),
        "types": array(string(max_length=200), description="ontology classes, most specific first"),
        "names": array(_WORDS, description="what people called it"),
        "objects": array(_OBJECT_REF),
        "asserted": Spec("any", description="what people said (types, names, by speaker)"),
        "inferred": Spec("any", description="what the reasoner inferred"),
    },
    description="an area of the conceptual map (keys as in a loci.say/1 AREA)",
)

CONCEPTS = MessageSchema(
    "loci.concepts",
    1,
    obj(
        {
            "areas": mapping(CONCEPT_AREA, description="area id (a string) → the area"),
            "objects": mapping(
                Spec("any", nullable=True), description="object name → {name, kind, area, node, ...}"
            ),
        },
        {"version": integer(minimum=0), "stamp": _STAMP},
    ),
    checks=(_concepts_checks,),
    description="the conceptual map: areas with their classes, types, names and objects",
)

#: What a ``loci.map_edit/1`` can do to the map.
MAP_EDIT_OPS = ("remove_doorway",)

MAP_EDIT = MessageSchema(
    "loci.map_edit",
    1,
    obj(
        {
            "op": string(choices=MAP_EDIT_OPS),
            "node": integer(minimum=0, description="the navigation node concerned"),
            "after_scan": number(
                nullable=True,
                description="the stamp of the last scan processed before the edit (none: before any)",
            ),
        },
        {
            "stamp": _STAMP,
            "reason": string(max_length=400, description="why, e.g. the answer to 'Was there a door here?'"),
        },
    ),
    description="a change of the map that scans do not explain (the tutor said a doorway was none)",
)

for _schema in (PEOPLE, OBJECTS, CONCEPTS, MAP_EDIT):
    SCHEMAS.register(_schema)
