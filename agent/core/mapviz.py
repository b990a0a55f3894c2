"""The layered map as one picture: occupancy, navigation graph, areas, concepts and objects.

:func:`render_layered_map` draws, bottom to top:

1. the occupancy grid (free white, walls black, unknown grey), enlarged ``scale`` times;
2. the **areas** (``loci.areas/1``): each area's nodes as a tinted blob (the convex hull of
   its nodes, grown by half a node distance) in the colour of its class; over them the
   robot's path (optional), a dot per scan in the colour of that scan's place label;
3. the navigation graph's **edges** (``loci.graph/1``), thin dark lines;
4. the **nodes**: place nodes as discs coloured by their label (room, corridor, doorway,
   hallway: :data:`knowledge.labels.CLASS_COLORS_BGR`, as in every label picture of the
   project; grey before any label), doorway nodes as a bar across the opening (its width
   and orientation) with a square at the centre, outlined in black;
5. each area's **name**: what the conceptual map (``loci.concepts/1`` snapshot,
   ``{"areas": {id: AREA}}``) knows — a name people gave ("kitchen / recreation room"
   when several), else the most specific type ("living room"), else the class — and below
   it ``area N · class``; the current area's tint has a thicker outline;
6. the **objects** (``[{"name", "kind", "x", "y"}]`` in the map frame, or ``"node"``
   instead of x and y as ``loci.objects/1`` gives them): a purple diamond with the name;
7. a title band and a legend band.

Graph and area documents are in the odometry frame; ``odom_to_map`` is the odometry
frame's pose in the map frame (the identity in the simulator, whose odometry starts at the
true pose). Nothing here talks to the bus or the reasoner: the caller passes the documents.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from knowledge.conceptual.lexicon import GENERIC_TYPES, kind_words
from knowledge.fileio import write_image
from knowledge.labels import CLASS_CODES, CLASS_COLORS_BGR, CLASS_NAMES, DOORWAY
from knowledge.metric.grid import OccupancyGrid

if TYPE_CHECKING:
    from knowledge.evaluation.real_logs import Truth

__all__ = ["LayeredMap", "area_caption", "class_colour", "draw_doors", "render_layered_map"]

Colour = tuple[int, int, int]

#: Nodes without a label, edges, text.
UNLABELLED: Colour = (150, 150, 150)
EDGE: Colour = (70, 70, 70)
TEXT: Colour = (25, 25, 25)
OBJECT: Colour = (160, 40, 160)
#: The picture's longer side aims at about this many pixels (the map is enlarged by a whole factor).
TARGET_SIDE = 1400
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_TITLE_BAND = 34
_LEGEND_BAND = 34


def class_colour(label: str | None) -> Colour:
    """The BGR colour of a place class (grey for None or an unknown class)."""
    code = CLASS_CODES.get(label or "")
    return CLASS_COLORS_BGR.get(code, UNLABELLED) if code is not None else UNLABELLED


@dataclass(frozen=True, eq=False)
class LayeredMap:
    """A rendered layered map.

    Attributes:
        image: ``(H, W, 3)`` uint8 BGR.
        grid: the occupancy grid drawn.
        scale: pixels per grid cell.
        top: rows of the title band above the map.
        odom_to_map: the odometry frame's pose in the map frame ``(x, y, theta)``.
    """

    image: np.ndarray
    grid: OccupancyGrid
    scale: int
    top: int
    odom_to_map: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def px(self, x: float, y: float, *, frame: str = "map") -> tuple[int, int]:
        """The pixel ``(column, row)`` of a point: map-frame metres, or ``frame="odom"``."""
        if frame == "odom":
            x, y = _transform(self.odom_to_map, x, y)
        elif frame != "map":
            raise ValueError(f"frame must be 'map' or 'odom', got {frame!r}")
        r, c = self.grid.world_to_cell_float(np.array([x, y], dtype=np.float64))
        return (round(float(c) * self.scale), round(float(r) * self.scale) + self.top)


def area_caption(area: Mapping[str, Any] | None, fallback_class: str | None = None) -> str:
    """What to call an area in the picture: a given name, else its most specific type, else its class.

    ``area`` is a conceptual AREA (``names``, ``types``, ``class``); several names are joined
    with " / " (two people may call one room differently).
    """
    a = area or {}
    names = [str(n) for n in (a.get("names") or []) if str(n).strip()]
    if names:
        return " / ".join(dict.fromkeys(names))
    for t in a.get("types") or []:
        words = kind_words(str(t))
        if words and words.replace(" ", "") not in GENERIC_TYPES:
            return words
    cls = a.get("class") or fallback_class
    return str(cls) if cls else "unknown"


def render_layered_map(
    grid: OccupancyGrid,
    graph_doc: Mapping[str, Any],
    areas_doc: Mapping[str, Any] | None = None,
    concepts: Mapping[str, Any] | None = None,
    objects: Sequence[Mapping[str, Any]] = (),
    out_png: str | Path | None = None,
    *,
    trajectory: Sequence[tuple[float, float, str | None]] = (),
    truth: Sequence[str | None] | None = None,
    title: str | None = None,
    odom_to_map: tuple[float, float, float] = (0.0, 0.0, 0.0),
    scale: int | None = None,
) -> LayeredMap:
    """Draw the layered map (see the module docstring); write it to ``out_png`` if given.

    Args:
        grid: the occupancy grid (map frame).
        graph_doc: a ``loci.graph/1`` message (:func:`agent.core.pipeline.graph_message`).
        areas_doc: a ``loci.areas/1`` message (:func:`agent.core.pipeline.areas_message`), or None.
        concepts: a ``loci.concepts/1`` snapshot ``{"areas": {id: AREA}, ...}`` (ids may be
            strings, as after JSON), or None.
        objects: ``{"name", "kind", "x", "y"}`` (map frame, metres) or ``{"name", "kind",
            "node"}`` mappings; objects at an unknown node are left out.
        trajectory: the robot's path as ``(x, y, label)`` in the odometry frame, drawn as
            small dots in the colour of each scan's place label, under the graph.
        truth: the true class at each point of ``trajectory`` (an evaluation): each dot gets
            a ring in that colour, so a wrong label shows as a dot in a ring of another colour.
        out_png: where to write the PNG (atomically), or None.
        title: a line above the map.
        odom_to_map: the odometry frame's pose in the map frame (metres, radians).
        scale: pixels per cell (None: the picture's longer side near :data:`TARGET_SIDE`).

    Raises:
        ValueError: ``scale`` below 1, or a document without its ``nodes``/``edges``/``areas``.
    """
    rows, cols = grid.shape
    k = max(1, round(TARGET_SIDE / max(rows, cols))) if scale is None else int(scale)
    if k < 1:
        raise ValueError(f"scale must be at least 1 pixel per cell, got {scale}")
    nodes, edges = _graph(graph_doc)
    o2m = (float(odom_to_map[0]), float(odom_to_map[1]), float(odom_to_map[2]))
    lm = LayeredMap(np.zeros((1, 1, 3), np.uint8), grid, k, _TITLE_BAND, o2m)

    base = cv2.cvtColor(grid.to_image(), cv2.COLOR_GRAY2BGR)
    base = cv2.resize(base, (cols * k, rows * k), interpolation=cv2.INTER_NEAREST)
    W = cols * k
    img = np.full((rows * k + _TITLE_BAND + _LEGEND_BAND, W, 3), 255, np.uint8)
    img[_TITLE_BAND : _TITLE_BAND + rows * k] = base
    unit = max(1, k)  # line widths and radii grow with the enlargement
    node_r = max(3, round(0.12 / grid.resolution * k))
    cell_m = grid.resolution / k

    pos = {nid: lm.px(n["x"], n["y"], frame="odom") for nid, n in nodes.items()}
    area_list = _areas(areas_doc)
    concept_areas = _concept_areas(concepts)

    # 2. areas
    tint = img.copy()
    outlines: list[tuple[np.ndarray, Colour, int]] = []
    for a in area_list:
        pts = np.array([pos[n] for n in a["nodes"] if n in pos], dtype=np.int32)
        if len(pts) == 0:
            continue
        colour = class_colour(a.get("label"))
        grow = max(node_r * 2, round(0.5 / cell_m))
        hull = _blob(pts, grow)
        cv2.fillPoly(tint, [hull], colour, cv2.LINE_AA)
        current = bool((concept_areas.get(int(a["id"])) or {}).get("current"))
        outlines.append((hull, colour, 3 * unit if current else unit))
    cv2.addWeighted(tint, 0.28, img, 0.72, 0, dst=img)
    for hull, colour, width in outlines:
        cv2.polylines(img, [hull], True, _darker(colour), width, cv2.LINE_AA)

    # 2b. the path, coloured by each scan's label
    dot = max(1, round(0.05 / cell_m))
    if truth is not None:
        if len(truth) != len(trajectory):
            raise ValueError(f"truth has {len(truth)} labels for {len(trajectory)} trajectory points")
        for (x, y, _), true in zip(trajectory, truth, strict=True):
            cv2.circle(img, lm.px(x, y, frame="odom"), 2 * dot + 1, class_colour(true), -1)
    for x, y, label in trajectory:
        cv2.circle(img, lm.px(x, y, frame="odom"), dot, _darker(class_colour(label)), -1)

    # 3. edges
    for a_id, b_id in edges:
        if a_id in pos and b_id in pos:
            cv2.line(img, pos[a_id], pos[b_id], EDGE, max(1, unit // 2), cv2.LINE_AA)

    # 5a. area captions go under the nodes' discs (the nodes matter more)
    for a in area_list:
        pts = np.array([pos[n] for n in a["nodes"] if n in pos], dtype=np.int32)
        if len(pts) == 0:
            continue
        concept = concept_areas.get(int(a["id"]))
        caption = area_caption(concept, a.get("label"))
        cls = (concept or {}).get("class") or a.get("label") or "?"
        cx = int(pts[:, 0].mean())
        top_y = int(pts[:, 1].min()) - node_r - 6
        anchor = (cx, top_y if top_y > _TITLE_BAND + 40 else int(pts[:, 1].max()) + node_r + 30)
        _text(img, caption, anchor, 0.55 + 0.1 * unit, TEXT, 2, centre=True)
        _text(
            img,
            f"area {a['id']} - {cls}",
            (anchor[0], anchor[1] + 18 + 4 * unit),
            0.4 + 0.05 * unit,
            TEXT,
            1,
            centre=True,
        )

    # 4. nodes
    for nid, n in nodes.items():
        p = pos[nid]
        if n.get("kind") == "doorway":
            _doorway(img, lm, n, node_r, unit)
        else:
            cv2.circle(img, p, node_r, class_colour(n.get("label")), -1, cv2.LINE_AA)
            cv2.circle(img, p, node_r, (40, 40, 40), 1, cv2.LINE_AA)

    # 6. objects
    stacked: dict[tuple[int, int], int] = {}
    for o in objects:
        at = _object_px(lm, o, nodes)
        if at is None:
            continue
        n_here = stacked.get(at, 0)
        stacked[at] = n_here + 1
        x, y = at[0], at[1] - n_here * (14 + 4 * unit)
        s = node_r + 2
        diamond = np.array([[x, y - s], [x + s, y], [x, y + s], [x - s, y]], np.int32)
        cv2.fillConvexPoly(img, diamond, OBJECT, cv2.LINE_AA)
        cv2.polylines(img, [diamond], True, (255, 255, 255), 1, cv2.LINE_AA)
        _text(
            img, str(o.get("name") or o.get("kind") or "?"), (x + s + 4, y + 5), 0.45 + 0.05 * unit, OBJECT, 1
        )

    # 7. title and legend
    _text(img, title or "layered map", (8, 23), 0.65, TEXT, 2)
    _legend(img, rows * k + _TITLE_BAND + 6)
    lm = LayeredMap(img, grid, k, _TITLE_BAND, lm.odom_to_map)
    if out_png is not None:
        write_image(Path(out_png), img)
    return lm


# ------------------------------------------------------------------------------ documents
def _graph(doc: Mapping[str, Any]) -> tuple[dict[int, Mapping[str, Any]], list[tuple[int, int]]]:
    try:
        nodes = {int(n["id"]): n for n in doc["nodes"]}
        edges = [(int(e[0]), int(e[1])) for e in doc["edges"]]
    except (KeyError, TypeError, IndexError, ValueError) as exc:
        raise ValueError(
            "graph_doc must be a loci.graph/1 message with 'nodes' [{id, x, y, kind, label}] and "
            "'edges' [[a, b]] (agent.core.pipeline.graph_message)"
        ) from exc
    for n in nodes.values():
        if not (math.isfinite(float(n["x"])) and math.isfinite(float(n["y"]))):
            raise ValueError(f"graph node {n['id']} has no finite position")
    return nodes, edges


def _areas(doc: Mapping[str, Any] | None) -> list[Mapping[str, Any]]:
    if doc is None:
        return []
    try:
        return [{**a, "id": int(a["id"]), "nodes": [int(k) for k in a["nodes"]]} for a in doc["areas"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(
            "areas_doc must be a loci.areas/1 message with 'areas' [{id, label, nodes}] "
            "(agent.core.pipeline.areas_message)"
        ) from exc


def _concept_areas(concepts: Mapping[str, Any] | None) -> dict[int, Mapping[str, Any]]:
    out: dict[int, Mapping[str, Any]] = {}
    areas = (concepts or {}).get("areas") or {}
    items = areas.items() if isinstance(areas, Mapping) else ((a.get("id"), a) for a in areas)
    for key, area in items:
        try:
            out[int(key)] = area
        except (TypeError, ValueError):
            continue
    return out


def _object_px(
    lm: LayeredMap, o: Mapping[str, Any], nodes: Mapping[int, Mapping[str, Any]]
) -> tuple[int, int] | None:
    if o.get("x") is not None and o.get("y") is not None:
        return lm.px(float(o["x"]), float(o["y"]))
    node = o.get("node")
    if node is not None and int(node) in nodes:
        n = nodes[int(node)]
        return lm.px(float(n["x"]), float(n["y"]), frame="odom")
    return None


# ------------------------------------------------------------------------------ drawing
def _transform(pose: Sequence[float], x: float, y: float) -> tuple[float, float]:
    px, py, th = pose
    c, s = math.cos(th), math.sin(th)
    return (px + c * x - s * y, py + s * x + c * y)


def _blob(pts: np.ndarray, grow: int) -> np.ndarray:
    """The convex hull of ``pts`` grown by ``grow`` pixels (a disc for one point)."""
    ang = np.linspace(0, 2 * math.pi, 16, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1) * grow
    cloud = (pts[:, None, :] + ring[None, :, :]).reshape(-1, 2)
    return cv2.convexHull(np.round(cloud).astype(np.int32))


def _darker(c: Colour) -> Colour:
    return (int(c[0] * 0.6), int(c[1] * 0.6), int(c[2] * 0.6))


def _doorway(img: np.ndarray, lm: LayeredMap, n: Mapping[str, Any], r: int, unit: int) -> None:
    """A bar across the opening (width, orientation) and a square at its centre."""
    x, y = float(n["x"]), float(n["y"])
    colour = class_colour("doorway")
    width = n.get("width")
    o = n.get("orientation")
    if width is not None and o is not None:
        half = 0.5 * float(width)
        t = float(o) + math.pi / 2  # along the opening
        a = lm.px(x - half * math.cos(t), y - half * math.sin(t), frame="odom")
        b = lm.px(x + half * math.cos(t), y + half * math.sin(t), frame="odom")
        cv2.line(img, a, b, (0, 0, 0), 2 * unit + 3, cv2.LINE_AA)
        cv2.line(img, a, b, colour, 2 * unit + 1, cv2.LINE_AA)
    cx, cy = lm.px(x, y, frame="odom")
    s = r + 1
    cv2.rectangle(img, (cx - s, cy - s), (cx + s, cy + s), colour, -1)
    cv2.rectangle(img, (cx - s, cy - s), (cx + s, cy + s), (0, 0, 0), 1)


def _text(
    img: np.ndarray,
    text: str,
    at: tuple[int, int],
    size: float,
    colour: Colour,
    thick: int,
    *,
    centre: bool = False,
) -> None:
    """Text with a white halo; ``at`` is its baseline's left end (or centre)."""
    (w, _h), _ = cv2.getTextSize(text, _FONT, size, thick)
    org = (at[0] - w // 2, at[1]) if centre else at
    cv2.putText(img, text, org, _FONT, size, (255, 255, 255), thick + 3, cv2.LINE_AA)
    cv2.putText(img, text, org, _FONT, size, colour, thick, cv2.LINE_AA)


def _legend(img: np.ndarray, y: int) -> None:
    x = 8
    entries: list[tuple[str, str, Colour]] = [
        *(
            ("disc", name, CLASS_COLORS_BGR[code])
            for code, name in sorted(CLASS_NAMES.items())
            if code != DOORWAY
        ),
        ("square", "doorway node", CLASS_COLORS_BGR[DOORWAY]),
        ("disc", "no label", UNLABELLED),
        ("diamond", "object", OBJECT),
    ]
    cy = y + 11
    for shape, name, colour in entries:
        if shape == "disc":
            cv2.circle(img, (x + 7, cy), 7, colour, -1, cv2.LINE_AA)
        elif shape == "square":
            cv2.rectangle(img, (x, cy - 7), (x + 14, cy + 7), colour, -1)
            cv2.rectangle(img, (x, cy - 7), (x + 14, cy + 7), (0, 0, 0), 1)
        else:
            d = np.array([[x + 7, cy - 8], [x + 15, cy], [x + 7, cy + 8], [x - 1, cy]], np.int32)
            cv2.fillConvexPoly(img, d, colour, cv2.LINE_AA)
        _text(img, name, (x + 20, cy + 5), 0.45, TEXT, 1)
        (w, _), _ = cv2.getTextSize(name, _FONT, 0.45, 1)
        x += 20 + w + 18
    _text(
        img,
        "tint: area (class colour); caption: what the conceptual map calls it",
        (x, cy + 5),
        0.42,
        TEXT,
        1,
    )


def draw_doors(lm: LayeredMap, truth: Truth, graph: Mapping[str, Any], doors: Mapping[str, Any]) -> None:
    """An evaluation's doors on a layered map (:func:`knowledge.evaluation.real_logs.evaluate`'s
    ``doors``): a circle of the match radius at each labelled door (green found, red missed,
    grey not driven through, violet room to room) and a cross on each false doorway node."""

    missed = {m["id"] for m in doors["missed"]}
    false = set(doors["false"])
    radius = max(3, round(doors["radius"] / lm.grid.resolution * lm.scale))
    for door in truth.doors:
        if not door.driven:
            colour = (150, 150, 150)
        elif door.room_to_room:
            colour = (200, 60, 160)
        else:
            colour = (40, 40, 220) if door.id in missed else (40, 160, 40)
        cv2.circle(lm.image, lm.px(*door.center, frame="odom"), radius, colour, 2, cv2.LINE_AA)
    for n in graph["nodes"]:
        if n["id"] in false:
            x, y = lm.px(n["x"], n["y"], frame="odom")
            k = max(4, radius // 2)
            cv2.line(lm.image, (x - k, y - k), (x + k, y + k), (0, 0, 0), 2, cv2.LINE_AA)
            cv2.line(lm.image, (x - k, y + k), (x + k, y - k), (0, 0, 0), 2, cv2.LINE_AA)
