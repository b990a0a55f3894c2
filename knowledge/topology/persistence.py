"""The navigation graph and its areas as one versioned JSON document (``loci.navgraph/1``).

The document (also the payload the agent publishes and answers queries with)::

    {
      "schema": "loci.navgraph/1",
      "frame": "odom",                               # the frame of every position
      "params": {"node_distance": m, "reach": m | null, "window": N,
                 "ignore_labels": [str], "door_merge": m,
                 "min_coverage": share},          # optional (documents before it: 0)
      "next_node_id": int,                          # ids are never reused
      "current": id | null,                         # the node the robot was last at
      "recent_labels": [str | null],                # the window of the last N place labels (null: abstained)
      "nodes": [{"id": int, "kind": "place" | "doorway", "x": m, "y": m,
                 "label": str | null, "votes": {label: count}, "visits": int,
                 "width": m | null, "orientation": rad | null}],
      "edges": [{"source": id, "target": id, "length": m}],     # source < target
      "areas": null | {"next_area_id": int,
                       "areas": [{"id": int, "label": str | null, "nodes": [id]}]},
      "meta": {...}                                 # free-form, e.g. the robot's name
    }

:func:`save` writes it atomically (temp file, fsync, rename: a reader or a restarted agent
sees the old file or the new one, never a torn one). :func:`load` and :func:`from_document`
validate everything before building anything: a malformed document, or one of a newer
schema version, raises :class:`~knowledge.errors.ProtocolError` saying what is wrong, and
no half-built graph is ever returned.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from knowledge.errors import ProtocolError
from knowledge.fileio import atomic_write_text
from knowledge.navigation.graph import NODE_KINDS, GraphParams, NavigationGraph
from knowledge.schema import MessageSchema, Spec, array, integer, mapping, number, obj, string
from knowledge.topology.areas import Area, AreaMap

__all__ = ["SCHEMA", "dumps", "from_document", "load", "loads", "save", "to_document"]

SCHEMA = "loci.navgraph/1"
SCHEMA_FAMILY = "loci.navgraph/"
VERSION = 1


def _num(v: float, nd: int = 6) -> float:
    return round(float(v), nd)


def to_document(
    graph: NavigationGraph, areas: AreaMap | None = None, *, meta: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """The JSON document of a graph (and its areas), as plain dicts, lists and numbers."""
    prm = graph.params
    nodes = []
    for k in sorted(graph.nodes):
        n = graph.nodes[k]
        nodes.append(
            {
                "id": n.id,
                "kind": n.kind,
                "x": _num(n.x),
                "y": _num(n.y),
                "label": n.label,
                "votes": dict(sorted(n.votes.items())),
                "visits": n.visits,
                "width": None if n.width is None else _num(n.width),
                "orientation": None if n.orientation is None else _num(n.orientation),
            }
        )
    return {
        "schema": SCHEMA,
        "frame": "odom",
        "params": {
            "node_distance": prm.node_distance,
            "reach": prm.reach,
            "window": prm.window,
            "ignore_labels": list(prm.ignore_labels),
            "door_merge": prm.door_merge,
            "min_coverage": prm.min_coverage,
        },
        "next_node_id": graph.next_id,
        "current": graph.current,
        "recent_labels": list(graph.recent),
        "nodes": nodes,
        "edges": [{"source": a, "target": b, "length": _num(w)} for a, b, w in graph.edges()],
        "areas": None
        if areas is None
        else {
            "next_area_id": areas.next_id,
            "areas": [{"id": a.id, "label": a.label, "nodes": sorted(a.nodes)} for a in areas.areas.values()],
        },
        "meta": dict(meta or {}),
    }


def dumps(doc: Mapping[str, Any]) -> str:
    """The document as compact, deterministic JSON text."""
    try:
        return json.dumps(doc, allow_nan=False, sort_keys=True, separators=(",", ":"))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"the navigation graph document is not plain JSON (check meta): {exc}") from exc


def loads(text: str | bytes) -> tuple[NavigationGraph, AreaMap | None]:
    """Parse and validate a document; see :func:`from_document`."""
    try:
        doc = json.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"not a {SCHEMA} document: invalid JSON ({exc})") from exc
    return from_document(doc)


def save(
    path: str | Path,
    graph: NavigationGraph,
    areas: AreaMap | None = None,
    *,
    meta: Mapping[str, Any] | None = None,
) -> Path:
    """Write the graph (and areas) to ``path`` atomically; returns the path."""
    return atomic_write_text(path, dumps(to_document(graph, areas, meta=meta)) + "\n")


def load(path: str | Path) -> tuple[NavigationGraph, AreaMap | None]:
    """Read a file written by :func:`save`. Raises :class:`ProtocolError` (or FileNotFoundError)."""
    p = Path(path)
    try:
        text = p.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{p}: no navigation graph file (a new map starts empty)") from None
    try:
        return loads(text)
    except ProtocolError as exc:
        raise ProtocolError(
            f"{p}: {exc}. The file is not a usable navigation graph: move it aside to start a new map"
        ) from exc


# ---------------------------------------------------------------------------- validation

_NODE = obj(
    {
        "id": integer(minimum=1),
        "kind": string(choices=NODE_KINDS),
        "x": number(description="metres"),
        "y": number(description="metres"),
        "label": string(max_length=64, nullable=True),
        "votes": mapping(integer(minimum=0), description="label -> votes"),
        "visits": integer(minimum=0),
        "width": number(nullable=True, description="metres (doorways)"),
        "orientation": number(nullable=True, description="radians (doorways)"),
    }
)
#: The one definition of the document: every field's type and range (:mod:`knowledge.schema`);
#: what spans fields (ids, edges, areas) is checked as the graph is built.
DOCUMENT = MessageSchema(
    "loci.navgraph",
    VERSION,
    obj(
        {
            "frame": string(choices=("odom",)),
            "params": obj(
                {
                    "node_distance": number(minimum=0),
                    "reach": number(minimum=0, nullable=True),
                    "window": integer(minimum=1),
                    "ignore_labels": array(string(max_length=64)),
                    "door_merge": number(minimum=0),
                },
                # documents written before min_coverage existed: every label voted then
                {"min_coverage": number(minimum=0, maximum=1)},
            ),
            "next_node_id": integer(minimum=1),
            "current": integer(minimum=1, nullable=True),
            "recent_labels": array(string(max_length=64, nullable=True)),
            "nodes": array(_NODE),
            "edges": array(obj({"source": integer(), "target": integer(), "length": number(minimum=0)})),
            "areas": obj(
                {
                    "next_area_id": integer(minimum=1),
                    "areas": array(
                        obj(
                            {
                                "id": integer(minimum=1),
                                "label": string(max_length=64, nullable=True),
                                "nodes": array(integer()),
                            }
                        )
                    ),
                },
                nullable=True,
            ),
        },
        {"meta": mapping(Spec("any", nullable=True), description="free-form, e.g. the robot's name")},
    ),
    description="the navigation graph and its areas, as persisted (navgraph.json)",
)


class _Bad(Exception):
    """An inconsistency across fields (turned into ProtocolError)."""


def check_schema(doc: Any) -> None:
    """Raise :class:`ProtocolError` unless ``doc`` is a ``loci.navgraph/1`` object."""
    if not isinstance(doc, dict):
        raise ProtocolError(f"not a {SCHEMA} document: expected a JSON object, got {type(doc).__name__}")
    schema = doc.get("schema")
    if not isinstance(schema, str) or not schema.startswith(SCHEMA_FAMILY):
        raise ProtocolError(f"not a navigation graph: schema {schema!r}, expected {SCHEMA!r}")
    if schema != SCHEMA:
        version = schema[len(SCHEMA_FAMILY) :]
        newer = version.isdigit() and int(version) > VERSION
        raise ProtocolError(
            f"navigation graph schema {schema!r} "
            + (
                "is newer than this genius-loci reads: upgrade genius-loci to load it"
                if newer
                else f"is not one this genius-loci reads ({SCHEMA!r})"
            )
        )


def from_document(doc: Any) -> tuple[NavigationGraph, AreaMap | None]:
    """Build the graph (and areas, if the document has them) from a validated document.

    Raises:
        ProtocolError: the document is not ``loci.navgraph/1`` or is inconsistent; the message
            names the offending field.
    """
    check_schema(doc)
    try:
        DOCUMENT.validate(doc)
    except ProtocolError as exc:
        raise ProtocolError(f"malformed {exc}") from None
    try:
        return _build(doc)
    except _Bad as exc:
        raise ProtocolError(f"malformed {SCHEMA} document: {exc}") from None
    except ValueError as exc:
        raise ProtocolError(f"inconsistent {SCHEMA} document: {exc}") from exc


def _build(doc: dict[str, Any]) -> tuple[NavigationGraph, AreaMap | None]:
    """The graph of a document whose fields have their types (:data:`DOCUMENT`)."""
    p = doc["params"]
    params = GraphParams(
        node_distance=float(p["node_distance"]),
        reach=None if p["reach"] is None else float(p["reach"]),
        window=p["window"],
        ignore_labels=tuple(p["ignore_labels"]),
        door_merge=float(p["door_merge"]),
        min_coverage=float(p.get("min_coverage", 0.0)),
    )
    g = NavigationGraph(params)
    next_id = doc["next_node_id"]
    for i, n in enumerate(doc["nodes"]):
        where = f"nodes[{i}]"
        nid = n["id"]
        if nid >= next_id:
            raise _Bad(f"{where}.id {nid} is not below next_node_id {next_id}")
        if nid in g.nodes:
            raise _Bad(f"{where}.id {nid} is repeated")
        node = g.add_node(
            n["kind"],
            (float(n["x"]), float(n["y"])),
            width=None if n["width"] is None else float(n["width"]),
            orientation=None if n["orientation"] is None else float(n["orientation"]),
            node_id=nid,
        )
        node.votes = {str(k): int(v) for k, v in n["votes"].items()}
        label = n["label"]
        if n["kind"] == "place" and label is not None and label not in node.votes:
            raise _Bad(f"{where}.label {label!r} has no votes")
        node.label = label if n["kind"] == "place" else "doorway"
        node.visits = n["visits"]
    for i, e in enumerate(doc["edges"]):
        a, b = e["source"], e["target"]
        if a not in g.nodes or b not in g.nodes or a == b:
            raise _Bad(f"edges[{i}] joins unknown or identical nodes ({a}, {b})")
        g.add_edge(a, b)
    current = doc["current"]
    if current is not None and current not in g.nodes:
        raise _Bad(f"current node {current} is not a node")
    g.recent.extend(doc["recent_labels"][-params.window :])
    g.current = current
    g._next_id = next_id
    return g, _build_areas(doc["areas"], g)


def _build_areas(raw: dict[str, Any] | None, g: NavigationGraph) -> AreaMap | None:
    if raw is None:
        return None
    out: list[Area] = []
    seen: set[int] = set()
    for i, d in enumerate(raw["areas"]):
        where = f"areas.areas[{i}]"
        nodes = frozenset(d["nodes"])
        bad = sorted(k for k in nodes if k not in g.nodes or g.nodes[k].kind != "place")
        if bad:
            raise _Bad(f"{where} holds {bad}, which are not place nodes of the graph")
        if nodes & seen:
            raise _Bad(f"{where} shares nodes {sorted(nodes & seen)} with another area")
        seen |= nodes
        out.append(Area(d["id"], d["label"], nodes))
    try:
        return AreaMap.restore(out, raw["next_area_id"])
    except ValueError as exc:
        raise _Bad(f"areas: {exc}") from exc
