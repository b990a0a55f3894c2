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
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from knowledge.errors import ProtocolError
from knowledge.fileio import atomic_write_text
from knowledge.navigation.graph import NODE_KINDS, GraphParams, NavigationGraph
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


class _Bad(Exception):
    """A validation failure (turned into ProtocolError with the document path)."""


def _get(d: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in d:
        raise _Bad(f"{where} lacks {key!r}")
    return d[key]


def _int(v: Any, where: str, lo: int | None = None) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise _Bad(f"{where} must be an integer, got {v!r}")
    if lo is not None and v < lo:
        raise _Bad(f"{where} must be >= {lo}, got {v}")
    return v


def _opt_float(v: Any, where: str) -> float | None:
    return None if v is None else _float(v, where)


def _float(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise _Bad(f"{where} must be a finite number, got {v!r}")
    return float(v)


def _str(v: Any, where: str, *, optional: bool = False) -> str | None:
    if v is None and optional:
        return None
    if not isinstance(v, str) or not v:
        raise _Bad(f"{where} must be a non-empty string, got {v!r}")
    return v


def _list(v: Any, where: str) -> list[Any]:
    if not isinstance(v, list):
        raise _Bad(f"{where} must be a list, got {type(v).__name__}")
    return v


def _dict(v: Any, where: str) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise _Bad(f"{where} must be an object, got {type(v).__name__}")
    return v


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
        return _build(doc)
    except _Bad as exc:
        raise ProtocolError(f"malformed {SCHEMA} document: {exc}") from None
    except ValueError as exc:
        raise ProtocolError(f"inconsistent {SCHEMA} document: {exc}") from exc


def _build(doc: dict[str, Any]) -> tuple[NavigationGraph, AreaMap | None]:
    frame = _get(doc, "frame", "the document")
    if frame != "odom":
        raise _Bad(f"frame must be 'odom', got {frame!r}")
    p = _dict(_get(doc, "params", "the document"), "params")
    ignore = _list(_get(p, "ignore_labels", "params"), "params.ignore_labels")
    params = GraphParams(
        node_distance=_float(_get(p, "node_distance", "params"), "params.node_distance"),
        reach=_opt_float(_get(p, "reach", "params"), "params.reach"),
        window=_int(_get(p, "window", "params"), "params.window", 1),
        ignore_labels=tuple(str(_str(v, "params.ignore_labels[]")) for v in ignore),
        door_merge=_float(_get(p, "door_merge", "params"), "params.door_merge"),
        # documents written before min_coverage existed: every label voted then
        min_coverage=_float(p["min_coverage"], "params.min_coverage") if "min_coverage" in p else 0.0,
    )
    g = NavigationGraph(params)
    next_id = _int(_get(doc, "next_node_id", "the document"), "next_node_id", 1)
    for i, raw in enumerate(_list(_get(doc, "nodes", "the document"), "nodes")):
        where = f"nodes[{i}]"
        n = _dict(raw, where)
        nid = _int(_get(n, "id", where), f"{where}.id", 1)
        if nid >= next_id:
            raise _Bad(f"{where}.id {nid} is not below next_node_id {next_id}")
        if nid in g.nodes:
            raise _Bad(f"{where}.id {nid} is repeated")
        kind = _get(n, "kind", where)
        if kind not in NODE_KINDS:
            raise _Bad(f"{where}.kind must be one of {NODE_KINDS}, got {kind!r}")
        votes = _dict(_get(n, "votes", where), f"{where}.votes")
        for k, v in votes.items():
            _int(v, f"{where}.votes[{k!r}]", 0)
        node = g.add_node(
            kind,
            (_float(_get(n, "x", where), f"{where}.x"), _float(_get(n, "y", where), f"{where}.y")),
            width=_opt_float(_get(n, "width", where), f"{where}.width"),
            orientation=_opt_float(_get(n, "orientation", where), f"{where}.orientation"),
            node_id=nid,
        )
        node.votes = {str(k): int(v) for k, v in votes.items()}
        label = _str(_get(n, "label", where), f"{where}.label", optional=True)
        if kind == "place" and label is not None and label not in votes:
            raise _Bad(f"{where}.label {label!r} has no votes")
        node.label = label if kind == "place" else "doorway"
        node.visits = _int(_get(n, "visits", where), f"{where}.visits", 0)
    for i, raw in enumerate(_list(_get(doc, "edges", "the document"), "edges")):
        where = f"edges[{i}]"
        e = _dict(raw, where)
        a = _int(_get(e, "source", where), f"{where}.source")
        b = _int(_get(e, "target", where), f"{where}.target")
        _float(_get(e, "length", where), f"{where}.length")
        if a not in g.nodes or b not in g.nodes or a == b:
            raise _Bad(f"{where} joins unknown or identical nodes ({a}, {b})")
        g.add_edge(a, b)
    current = _get(doc, "current", "the document")
    if current is not None and (_int(current, "current") not in g.nodes):
        raise _Bad(f"current node {current} is not a node")
    labels = _list(_get(doc, "recent_labels", "the document"), "recent_labels")
    g.recent.extend(_str(v, "recent_labels[]", optional=True) for v in labels[-params.window :])
    g.current = current
    g._next_id = next_id
    areas = _build_areas(doc, g)
    return g, areas


def _build_areas(doc: dict[str, Any], g: NavigationGraph) -> AreaMap | None:
    raw = _get(doc, "areas", "the document")
    if raw is None:
        return None
    a = _dict(raw, "areas")
    next_id = _int(_get(a, "next_area_id", "areas"), "areas.next_area_id", 1)
    out: list[Area] = []
    seen: set[int] = set()
    for i, r in enumerate(_list(_get(a, "areas", "areas"), "areas.areas")):
        where = f"areas.areas[{i}]"
        d = _dict(r, where)
        aid = _int(_get(d, "id", where), f"{where}.id", 1)
        nodes = frozenset(
            _int(v, f"{where}.nodes[]") for v in _list(_get(d, "nodes", where), f"{where}.nodes")
        )
        bad = sorted(k for k in nodes if k not in g.nodes or g.nodes[k].kind != "place")
        if bad:
            raise _Bad(f"{where} holds {bad}, which are not place nodes of the graph")
        if nodes & seen:
            raise _Bad(f"{where} shares nodes {sorted(nodes & seen)} with another area")
        seen |= nodes
        out.append(Area(aid, _str(_get(d, "label", where), f"{where}.label", optional=True), nodes))
    try:
        return AreaMap.restore(out, next_id)
    except ValueError as exc:
        raise _Bad(f"areas: {exc}") from exc
