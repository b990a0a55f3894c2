"""JSON messages: validation on receipt with clear reasons, and the JSON Schema documents."""

from __future__ import annotations

import json
import math
import os
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.bus.codecs import json_codec
from agent.bus.schemas import SCHEMAS, MessageSchema, SchemaRegistry, integer, obj
from knowledge.errors import ProtocolError
from knowledge.schema import Spec, check_value


def _place(**over: Any) -> dict[str, Any]:
    msg = {
        "schema": "loci.place/1",
        "stamp": 1.5,
        "label": "corridor",
        "probabilities": {"room": 0.2, "corridor": 0.8},
        "node": 3,
    }
    msg.update(over)
    return msg


def _graph() -> dict[str, Any]:
    return {
        "schema": "loci.graph/1",
        "stamp": 2.0,
        "nodes": [
            {"id": 0, "x": 0.0, "y": 0.0, "kind": "place", "label": "room"},
            {
                "id": 1,
                "x": 1.0,
                "y": 0.0,
                "kind": "doorway",
                "label": None,
                "width": 0.9,
                "orientation": 1.57,
            },
        ],
        "edges": [[0, 1]],
    }


def test_valid_messages_round_trip() -> None:
    codec = json_codec("loci.place/1")
    assert codec.decode(codec.encode(_place())) == _place()
    graph = json_codec("loci.graph/1")
    assert graph.decode(graph.encode(_graph())) == _graph()
    areas = {"schema": "loci.areas/1", "stamp": 0, "areas": [{"id": 0, "label": "room", "nodes": [0, 1]}]}
    assert SCHEMAS.decode(json.dumps(areas).encode()) == areas


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"{not json", "not valid JSON"),
        (b'{"schema": "loci.place/1", "stamp": NaN}', "NaN"),
        (b"[1, 2]", "JSON object"),
        (b'{"stamp": 1}', "'schema' string"),
        (json.dumps(_place(schema="loci.graph/1")).encode(), "expected a loci.place/1"),
        (
            json.dumps({k: v for k, v in _place().items() if k != "label"}).encode(),
            "missing required field 'label'",
        ),
        (json.dumps(_place(label=3)).encode(), r"loci.place/1.label: expected a string"),
        (json.dumps(_place(probabilities={"room": 1.5})).encode(), r"probabilities.room: 1.5 is above"),
        (json.dumps(_place(node=True)).encode(), "node: expected an integer, got a boolean"),
        (json.dumps(_place(node=-1)).encode(), "below the minimum"),
        (json.dumps(_place(stamp="now")).encode(), "stamp: expected a number"),
        (b"\xff\xfe", "not valid JSON"),
    ],
)
def test_malformed_messages_say_what_is_wrong(payload: bytes, reason: str) -> None:
    with pytest.raises(ProtocolError, match=reason):
        SCHEMAS.decode(payload, "loci.place/1")


def test_unknown_schemas_are_named() -> None:
    with pytest.raises(
        ProtocolError, match=r"unknown message schema 'loci.nothing/1' \(known: .*loci.place/1"
    ):
        SCHEMAS.decode(json.dumps(_place(schema="loci.nothing/1")).encode())


def test_graph_cross_checks() -> None:
    bad = _graph()
    bad["edges"].append([1, 7])
    with pytest.raises(ProtocolError, match=r"edges\[1\].*not in 'nodes'"):
        SCHEMAS.validate(bad)
    dup = _graph()
    dup["nodes"][1]["id"] = 0
    dup["edges"] = []
    with pytest.raises(ProtocolError, match="unique"):
        SCHEMAS.validate(dup)
    kind = _graph()
    kind["nodes"][0]["kind"] = "kitchen"
    with pytest.raises(ProtocolError, match=r"nodes\[0\].kind: 'kitchen' is not one of place, doorway"):
        SCHEMAS.validate(kind)


def test_encoding_refuses_invalid_messages_and_non_json_values() -> None:
    with pytest.raises(ProtocolError, match="missing required field"):
        SCHEMAS.encode({"schema": "loci.place/1"})
    with pytest.raises(ProtocolError):
        SCHEMAS.encode(_place(stamp=float("inf")))


def test_registry_refuses_a_changed_schema_under_a_known_id() -> None:
    reg = SchemaRegistry()
    first = reg.register(MessageSchema("loci.test", 1, obj({"n": integer()})))
    reg.register(first)  # the same object again is fine
    with pytest.raises(ValueError, match="bump the version"):
        reg.register(MessageSchema("loci.test", 1, obj({"n": integer(minimum=0)})))
    with pytest.raises(ValueError, match="must look like"):
        MessageSchema("Loci.Test", 1, obj())


def test_json_schema_documents_describe_the_fields() -> None:
    for sid in SCHEMAS.ids():
        doc = SCHEMAS.get(sid).json_schema()
        assert doc["$id"] == sid and doc["type"] == "object"
        assert doc["properties"]["schema"] == {"const": sid}
        assert "schema" in doc["required"]
        json.dumps(doc)  # plain JSON
    place = SCHEMAS.get("loci.place/1").json_schema()
    assert set(place["required"]) == {"schema", "stamp", "label", "probabilities"}
    assert place["properties"]["node"]["type"] == ["integer", "null"]
    assert place["properties"]["probabilities"]["additionalProperties"]["maximum"] == 1


def test_the_docs_show_every_schema_as_the_code_checks_it() -> None:
    """docs/bus.md's field table is made from the registry: a schema changed in the code and
    not in the docs (or the other way round) fails here, with the table to paste."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "bus.md").read_text(encoding="utf-8")
    shown = doc.split("<!-- schemas:begin -->\n", 1)[1].split("\n<!-- schemas:end -->", 1)[0]
    assert shown == SCHEMAS.markdown_table(), "docs/bus.md is stale; paste:\n" + SCHEMAS.markdown_table()


# ---- the compiled (msgspec) validator against the walk of the spec ------------------------
def _example(spec: Spec, draw: st.DrawFn, depth: int = 0) -> Any:
    """A value ``spec`` accepts (mostly), drawn by hypothesis."""
    if spec.nullable and draw(st.booleans()):
        return None
    k = spec.kind
    if k == "string":
        if spec.choices:
            return draw(st.sampled_from(spec.choices))
        return draw(st.text(max_size=min(spec.max_length or 8, 8)))
    if k in ("number", "integer"):
        lo = -1e6 if spec.minimum is None else spec.minimum
        hi = 1e6 if spec.maximum is None else spec.maximum
        if k == "integer":
            return draw(st.integers(math.ceil(lo), math.floor(hi)))
        return draw(st.floats(lo, hi, allow_nan=False))
    if k == "boolean":
        return draw(st.booleans())
    if k == "array":
        assert spec.items is not None
        lo = spec.min_items or 0
        n = draw(st.integers(lo, max(lo, min(spec.max_items or 3, 3))))
        return [_example(spec.items, draw, depth + 1) for _ in range(n)]
    if k == "object" and spec.values is not None:
        return {
            draw(st.text(max_size=4)): _example(spec.values, draw, depth + 1)
            for _ in range(draw(st.integers(0, 2)))
        }
    if k == "object":
        out = {key: _example(sub, draw, depth + 1) for key, sub in spec.required.items()}
        for key, sub in spec.optional.items():
            if draw(st.booleans()):
                out[key] = _example(sub, draw, depth + 1)
        return out
    return draw(_JSON)


_JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=8,
)


def _mutate(value: Any, draw: st.DrawFn) -> Any:
    """Replace, drop or add one thing somewhere in ``value``."""
    if isinstance(value, dict) and value and draw(st.booleans()):
        key = draw(st.sampled_from(sorted(value, key=str)))
        choice = draw(st.integers(0, 2))
        if choice == 0:
            return {k: v for k, v in value.items() if k != key}
        if choice == 1:
            return {**value, key: _mutate(value[key], draw)}
        return {**value, draw(st.text(max_size=4)): draw(_JSON)}
    if isinstance(value, list) and value and draw(st.booleans()):
        i = draw(st.integers(0, len(value) - 1))
        return [*value[:i], _mutate(value[i], draw), *value[i + 1 :]]
    return draw(_JSON)


@settings(max_examples=int(os.environ.get("LOCI_EXAMPLES", "300")), deadline=None)
@given(st.data())
def test_the_compiled_validator_accepts_nothing_the_spec_refuses(data: st.DataObject) -> None:
    """Every schema's msgspec type (the fast path on receipt) accepts only what the walk of
    its spec accepts, on valid messages and on messages with one thing changed: a refusal is
    explained by the walk, an acceptance is never a message the walk would refuse."""
    import msgspec

    sid = data.draw(st.sampled_from(SCHEMAS.ids()))
    schema = SCHEMAS.get(sid)
    message = {"schema": sid, **_example(schema.body, data.draw)}
    for candidate in (message, _mutate(message, data.draw)):
        try:
            msgspec.convert(candidate, type=schema.compiled)
        except msgspec.ValidationError:
            continue
        check_value(schema.body, candidate, sid)  # must not raise


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_every_message_type_round_trips(data: st.DataObject) -> None:
    """Any message a schema accepts comes back from encode then decode as it went in."""
    sid = data.draw(st.sampled_from(SCHEMAS.ids()))
    schema = SCHEMAS.get(sid)
    message = {"schema": sid, **_example(schema.body, data.draw)}
    try:
        schema.validate(message)
    except ProtocolError:
        return  # a drawn example that breaks a cross-field rule (two nodes with one id)
    assert SCHEMAS.decode(SCHEMAS.encode(message, sid), sid) == message
