"""The topological map as a JSON document (schema ``loci.topomap/1``) and as pictures.

The document (see docs/topology.md for the full description)::

    {
      "schema": "loci.topomap/1",
      "map": {"name": str, "resolution": m, "origin": [x, y, yaw], "rows": int, "cols": int,
              "frame": "world"},
      "classes": {"1": "room", ...},             # label code -> class name
      "connectivity": 8,
      "thresholds": {...} | null,                # CorrectionThresholds.to_dict()
      "nodes": [{"id", "code", "label", "cells", "area_m2", "centroid": [x, y],
                 "centroid_cell": [row, col], "major_axis": [x, y], "minor_axis": [x, y],
                 "elongation", "orientation_rad", "bbox_cells": [row0, col0, row1, col1],
                 "degree"}],
      "edges": [{"source": id, "target": id, "border_m", "border_cells"}],
      "corrections": [{"round", "from", "to", "reason", "cells", "area_m2",
                       "centroid": [x, y]}],
      "meta": {...}                              # free-form, e.g. relaxation settings
    }

Node ids are the pixel values of the region-id image (:func:`region_image`). World
coordinates are metres in the map's frame (x right, y up, as in ROS), axes are the ellipse's
semi-axes as vectors.

Pictures are BGR ``uint8`` arrays; the caller writes them (e.g. with
:func:`knowledge.fileio.write_image`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from knowledge.errors import ProtocolError
from knowledge.labels import CLASS_COLORS_BGR, CLASS_NAMES, overlay
from knowledge.metric.grid import OccupancyGrid
from knowledge.places.regions import CorrectionThresholds, Merge, RegionGraph
from knowledge.schema import MessageSchema, Spec, array, integer, mapping, number, obj, string

SCHEMA = "loci.topomap/1"


def _graph_checks(doc: dict[str, Any]) -> str | None:
    ids = {n["id"] for n in doc["nodes"]}
    if len(ids) != len(doc["nodes"]):
        return "node ids must be unique"
    for i, e in enumerate(doc["edges"]):
        if e["source"] not in ids or e["target"] not in ids:
            return f"edge {i} joins unknown nodes {e['source']}–{e['target']}"
    return None


def _r(x: float, nd: int = 4) -> float:
    return round(float(x), nd)


def topomap_document(
    graph: RegionGraph,
    grid: OccupancyGrid,
    *,
    thresholds: CorrectionThresholds | None = None,
    merges: Sequence[Merge] = (),
    class_names: Mapping[int, str] | None = None,
    meta: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON document of a region graph on ``grid`` (plain dicts, lists and numbers)."""
    if graph.ids.shape != grid.shape:
        raise ValueError(f"region image {graph.ids.shape} and grid {grid.shape} differ in shape")
    names = dict(CLASS_NAMES)
    if class_names:
        names.update({int(k): str(v) for k, v in class_names.items()})
    degree = {r.id: 0 for r in graph.regions}
    for e in graph.edges:
        degree[e.a] += 1
        degree[e.b] += 1
    nodes = []
    for reg in graph.regions:
        nodes.append(
            {
                "id": reg.id,
                "code": reg.label,
                "label": names.get(reg.label, f"code{reg.label}"),
                "cells": reg.cells,
                "area_m2": _r(reg.area_m2),
                "centroid": [_r(v) for v in reg.centroid],
                "centroid_cell": [_r(v, 2) for v in reg.centroid_cell],
                "major_axis": [_r(v) for v in reg.major_axis],
                "minor_axis": [_r(v) for v in reg.minor_axis],
                "elongation": _r(reg.elongation, 3),
                "orientation_rad": _r(reg.orientation),
                "bbox_cells": list(reg.bbox),
                "degree": degree[reg.id],
            }
        )
    edges = [
        {"source": e.a, "target": e.b, "border_m": _r(e.border_m), "border_cells": _r(e.border_cells, 1)}
        for e in graph.edges
    ]
    corrections = []
    for m in merges:
        cx, cy = grid.cell_to_world(np.asarray(m.centroid_cell))
        corrections.append(
            {
                "round": m.round,
                "from": names.get(m.label_from, f"code{m.label_from}"),
                "to": names.get(m.label_to, f"code{m.label_to}"),
                "reason": m.reason,
                "cells": m.cells,
                "area_m2": _r(m.area_m2),
                "centroid": [_r(cx), _r(cy)],
            }
        )
    used = sorted({r.label for r in graph.regions} | {m.label_from for m in merges})
    rows, cols = grid.shape
    return {
        "schema": SCHEMA,
        "map": {
            "name": grid.name,
            "resolution": grid.resolution,
            "origin": list(grid.origin),
            "rows": rows,
            "cols": cols,
            "frame": "world",
        },
        "classes": {str(c): names.get(c, f"code{c}") for c in used},
        "connectivity": graph.connectivity,
        "thresholds": thresholds.to_dict() if thresholds is not None else None,
        "nodes": nodes,
        "edges": edges,
        "corrections": corrections,
        "meta": dict(meta or {}),
    }


def dumps(doc: Mapping[str, Any]) -> str:
    """The document as JSON text (validated first), one node or edge per line."""
    validate_document(doc)
    head = {k: v for k, v in doc.items() if k not in ("nodes", "edges", "corrections")}
    parts = ["{"]
    for k, v in head.items():
        parts.append(f"  {json.dumps(k)}: {json.dumps(v)},")
    for i, key in enumerate(("nodes", "edges", "corrections")):
        items = doc.get(key, [])
        body = ",\n".join(f"    {json.dumps(x)}" for x in items)
        tail = "," if i < 2 else ""
        parts.append(f'  "{key}": [\n{body}\n  ]{tail}' if items else f'  "{key}": []{tail}')
    parts.append("}")
    return "\n".join(parts) + "\n"


def loads(text: str) -> dict[str, Any]:
    """Parse and validate a topological map document."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ProtocolError(f"a topological map must be JSON: {exc}") from exc
    return validate_document(doc)


_PAIR = array(number(), min_items=2, max_items=2)
#: The one definition of the document's fields (:mod:`knowledge.schema`).
DOCUMENT = MessageSchema(
    "loci.topomap",
    1,
    obj(
        {
            "map": obj(
                {
                    "resolution": number(minimum=0),
                    "origin": array(number(), min_items=3, max_items=3),
                    "rows": integer(minimum=1),
                    "cols": integer(minimum=1),
                },
                {"name": string(), "frame": string()},
            ),
            "nodes": array(
                obj(
                    {
                        "id": integer(),
                        "code": integer(minimum=0),
                        "label": string(),
                        "cells": integer(minimum=0),
                        "area_m2": number(minimum=0),
                        "centroid": _PAIR,
                        "centroid_cell": _PAIR,
                        "major_axis": _PAIR,
                        "minor_axis": _PAIR,
                        "elongation": number(),
                        "orientation_rad": number(),
                        "bbox_cells": array(integer(), min_items=4, max_items=4),
                        "degree": integer(minimum=0),
                    }
                )
            ),
            "edges": array(
                obj(
                    {"source": integer(), "target": integer(), "border_m": number(), "border_cells": number()}
                )
            ),
        },
        {
            "classes": mapping(string()),
            "connectivity": integer(),
            "thresholds": Spec("object", nullable=True, values=Spec("any", nullable=True)),
            "corrections": array(mapping(Spec("any", nullable=True))),
            "meta": mapping(Spec("any", nullable=True)),
        },
    ),
    checks=(_graph_checks,),
    description="the topological map of regions (loci places topology)",
)


def validate_document(doc: Any) -> dict[str, Any]:
    """Check a document's schema and structure; returns it. Raises :class:`ProtocolError`."""
    if not isinstance(doc, dict):
        raise ProtocolError("a topological map document must be a JSON object")
    if doc.get("schema") != SCHEMA:
        raise ProtocolError(f"expected schema {SCHEMA!r}, got {doc.get('schema')!r}")
    DOCUMENT.validate(doc)
    return doc


def region_image(graph: RegionGraph) -> np.ndarray:
    """The region ids as a ``(rows, cols)`` uint16 image (for a 16-bit PNG); 0 = no region."""
    n = len(graph.regions)
    if n > 65535:
        raise ValueError(f"{n} regions do not fit a 16-bit image (at most 65535)")
    return graph.ids.astype(np.uint16)


# ---------------------------------------------------------------------- pictures
def map_background(grid: OccupancyGrid) -> np.ndarray:
    """A grey picture of the grid: free light, occupied black, unknown mid grey."""
    img = np.full(grid.shape, 150, dtype=np.uint8)
    img[grid.free] = 235
    img[grid.occupied] = 0
    return img


def draw_labels(background: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Labels coloured over the map (:func:`knowledge.labels.overlay`)."""
    return overlay(background, np.asarray(labels))


def region_colours(n: int, seed: int = 7) -> np.ndarray:
    """``(n + 1, 3)`` uint8 BGR colours, index 0 black, the others well apart in hue."""
    hues = (np.arange(n) * 0.618033988749895 + 0.1) % 1.0
    rng = np.random.default_rng(seed)
    sat = rng.uniform(0.55, 0.95, n)
    val = rng.uniform(0.7, 1.0, n)
    hsv = np.stack([hues * 180, sat * 255, val * 255], axis=1).astype(np.uint8)[None]
    bgr = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0]
    return np.concatenate([np.zeros((1, 3), np.uint8), bgr])


def draw_regions(graph: RegionGraph, background: np.ndarray | None = None) -> np.ndarray:
    """Every region in its own colour; cells outside regions show the (darkened) background."""
    colours = region_colours(len(graph.regions))
    out = colours[graph.ids]
    if background is not None:
        bg = np.asarray(background, dtype=np.uint8)
        if bg.shape != graph.ids.shape:
            raise ValueError(f"background {bg.shape} and regions {graph.ids.shape} differ in shape")
        none = graph.ids == 0
        out[none] = (bg[none, None] // 2).repeat(3, axis=1)
    return np.ascontiguousarray(out)


def draw_graph(
    graph: RegionGraph,
    background: np.ndarray,
    labels: np.ndarray | None = None,
    *,
    ellipses: bool = True,
    ids: bool = True,
) -> np.ndarray:
    """The region graph over the map: edges as lines between centroids, nodes as discs in
    their class colour, optionally the ellipses and the node ids."""
    bg = np.asarray(background, dtype=np.uint8)
    if bg.shape != graph.ids.shape:
        raise ValueError(f"background {bg.shape} and regions {graph.ids.shape} differ in shape")
    lab = graph.labels() if labels is None else np.asarray(labels)
    img = overlay(bg, lab, alpha=0.35)
    size = max(bg.shape)
    thick = max(1, round(size / 600))
    radius = max(3, round(size / 150))
    font = max(0.35, size / 1500)
    shift = 4  # sub-pixel drawing with 4 fractional bits

    def pt(rc: tuple[float, float]) -> tuple[int, int]:
        return (round(rc[1] * (1 << shift)), round(rc[0] * (1 << shift)))

    if ellipses:
        for reg in graph.regions:
            dr, dc = reg.major_axis_cells
            a = math.hypot(dr, dc)
            b = math.hypot(*reg.minor_axis_cells)
            angle = math.degrees(math.atan2(dr, dc))  # image frame: x = col, y = row
            colour = _class_colour(reg.label)
            axes = (max(1, round(a * (1 << shift))), max(1, round(b * (1 << shift))))
            cv2.ellipse(img, pt(reg.centroid_cell), axes, angle, 0, 360, colour, thick, cv2.LINE_AA, shift)
    for e in graph.edges:
        pa = pt(graph.region(e.a).centroid_cell)
        pb = pt(graph.region(e.b).centroid_cell)
        cv2.line(img, pa, pb, (30, 30, 30), thick + 1, cv2.LINE_AA, shift)
    for reg in graph.regions:
        c = pt(reg.centroid_cell)
        cv2.circle(img, c, radius << shift, _class_colour(reg.label), -1, cv2.LINE_AA, shift)
        cv2.circle(img, c, radius << shift, (0, 0, 0), max(1, thick // 2), cv2.LINE_AA, shift)
        if ids:
            org = (round(reg.centroid_cell[1]) + radius + 1, round(reg.centroid_cell[0]) - radius - 1)
            cv2.putText(img, str(reg.id), org, cv2.FONT_HERSHEY_SIMPLEX, font, (0, 0, 0), thick, cv2.LINE_AA)
    return img


def _class_colour(code: int) -> tuple[int, int, int]:
    return CLASS_COLORS_BGR.get(code, (160, 160, 160))


def overview(
    panels: Sequence[tuple[str, np.ndarray]], *, columns: int = 2, max_side: int = 1200
) -> np.ndarray:
    """Captioned pictures in a grid (each scaled so its longer side is at most ``max_side``)."""
    if not panels:
        raise ValueError("overview needs at least one picture")
    tiles = []
    for title, pic in panels:
        p: np.ndarray = np.asarray(pic, dtype=np.uint8)
        if p.ndim == 2:
            p = cv2.cvtColor(p, cv2.COLOR_GRAY2BGR)
        s = min(1.0, max_side / max(p.shape[:2]))
        if s < 1.0:
            p = cv2.resize(p, (round(p.shape[1] * s), round(p.shape[0] * s)), interpolation=cv2.INTER_AREA)
        bar = np.full((28, p.shape[1], 3), 255, np.uint8)
        cv2.putText(bar, title, (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(np.concatenate([bar, p], axis=0))
    h = max(t.shape[0] for t in tiles)
    w = max(t.shape[1] for t in tiles)
    padded = [
        cv2.copyMakeBorder(
            t, 0, h - t.shape[0], 0, w - t.shape[1], cv2.BORDER_CONSTANT, value=(255, 255, 255)
        )
        for t in tiles
    ]
    while len(padded) % columns:
        padded.append(np.full((h, w, 3), 255, np.uint8))
    rows = [np.concatenate(padded[i : i + columns], axis=1) for i in range(0, len(padded), columns)]
    return np.concatenate(rows, axis=0)
