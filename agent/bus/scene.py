"""``foxglove.SceneUpdate`` pictures of the navigation graph and the areas (Foxglove 3D panel).

Built from plain dicts so the core's classes need not know Foxglove:

* graph: ``{"nodes": [{"id", "x", "y", "kind", "label"}, ...], "edges": [[a, b], ...]}``
  (the ``loci.graph/1`` message is such a dict); ``kind`` is ``"place"`` or ``"doorway"``,
  ``label`` a class name or None; positions in metres in ``frame_id``. Edges may also be
  ``{"source": a, "target": b, ...}`` objects, as in the ``loci.navgraph/1`` document.
* areas: ``{"areas": [{"id", "label", "nodes": [node ids]}, ...]}`` (``loci.areas/1``).
* people: ``{"legs": [[x, y], ...], "tracks": [{"id", "x", "y", "vx", "vy", ...}], "frame_id"}``
  (``loci.people/1``).

The graph is one entity ``graph``: a sphere per node coloured by its class (doorway nodes in
the doorway colour, unlabelled nodes grey), and the edges as one line list. The areas are
one entity ``areas``: a text label per area over the centroid of its nodes. The people are
one entity ``people``: a cylinder per confirmed track (a body of :data:`PERSON_SIZE`) with its
id above it and an arrow of its velocity, and a small sphere per detected leg. Each update
replaces the whole entity, so nodes or areas that disappeared disappear from the picture.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from foxglove import messages as fg

from knowledge.labels import CLASS_CODES, CLASS_COLORS_BGR

#: Sphere diameter of a node, metres.
NODE_SIZE = 0.25
#: A person's cylinder: diameter and height, metres.
PERSON_SIZE = (0.5, 1.7)
#: Sphere diameter of a leg, metres.
LEG_SIZE = 0.12
_PERSON_RGBA = (0.95, 0.55, 0.1, 0.8)
_UNKNOWN_RGBA = (0.6, 0.6, 0.6, 1.0)


def class_rgba(label: str | None) -> tuple[float, float, float, float]:
    """The overlay colour of a place class (RGBA in 0..1); grey for None or unknown classes."""
    code = CLASS_CODES.get(label or "")
    if code is None or code not in CLASS_COLORS_BGR:
        return _UNKNOWN_RGBA
    b, g, r = CLASS_COLORS_BGR[code]
    return (r / 255.0, g / 255.0, b / 255.0, 1.0)


def _color(rgba: tuple[float, float, float, float]) -> fg.Color:
    return fg.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _stamp(stamp: float) -> fg.Timestamp:
    return fg.Timestamp.from_epoch_secs(max(0.0, float(stamp)))


def _pose(x: float, y: float, z: float = 0.0) -> fg.Pose:
    return fg.Pose(position=fg.Vector3(x=x, y=y, z=z), orientation=fg.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def _node_positions(graph: Mapping[str, Any]) -> dict[int, tuple[float, float]]:
    return {int(n["id"]): (float(n["x"]), float(n["y"])) for n in graph.get("nodes", ())}


def area_centroids(
    areas: Mapping[str, Any], graph: Mapping[str, Any]
) -> list[tuple[Mapping[str, Any], float, float]]:
    """Each area of a ``loci.areas/1`` message with the centroid of its nodes in ``graph``
    (``loci.graph/1``); nodes missing from the graph are ignored, an area with none is left out."""
    pos = _node_positions(graph)
    out = []
    for area in areas.get("areas", ()):
        xy = [pos[int(n)] for n in area.get("nodes", ()) if int(n) in pos]
        if xy:
            out.append((area, sum(p[0] for p in xy) / len(xy), sum(p[1] for p in xy) / len(xy)))
    return out


def graph_scene(
    graph: Mapping[str, Any], *, frame_id: str = "odom", stamp: float | None = None
) -> fg.SceneUpdate:
    """The navigation graph as a SceneUpdate (entity ``graph``).

    ``stamp`` defaults to ``graph["stamp"]`` (seconds since the epoch), else 0.
    """
    when = _stamp(graph.get("stamp", 0.0) if stamp is None else stamp)
    spheres = []
    for n in graph.get("nodes", ()):
        label = "doorway" if n.get("kind") == "doorway" else n.get("label")
        spheres.append(
            fg.SpherePrimitive(
                pose=_pose(float(n["x"]), float(n["y"])),
                size=fg.Vector3(x=NODE_SIZE, y=NODE_SIZE, z=NODE_SIZE),
                color=_color(class_rgba(label)),
            )
        )
    pos = _node_positions(graph)
    points = []
    for edge in graph.get("edges", ()):
        a, b = (edge["source"], edge["target"]) if isinstance(edge, Mapping) else edge
        if int(a) in pos and int(b) in pos:
            for nid in (int(a), int(b)):
                x, y = pos[nid]
                points.append(fg.Point3(x=x, y=y, z=0.0))
    lines = []
    if points:
        lines.append(
            fg.LinePrimitive(
                type=fg.LinePrimitiveLineType.LineList,
                pose=_pose(0.0, 0.0),
                thickness=0.04,
                points=points,
                color=_color((0.2, 0.2, 0.2, 1.0)),
            )
        )
    entity = fg.SceneEntity(timestamp=when, frame_id=frame_id, id="graph", spheres=spheres, lines=lines)
    return fg.SceneUpdate(entities=[entity])


def areas_scene(
    areas: Mapping[str, Any], graph: Mapping[str, Any], *, frame_id: str = "odom", stamp: float | None = None
) -> fg.SceneUpdate:
    """The areas as a SceneUpdate (entity ``areas``): each area's class over its nodes' centroid.

    ``graph`` gives the node positions; nodes of an area missing from it are ignored, and an
    area with none of its nodes in the graph is not drawn.
    """
    when = _stamp(areas.get("stamp", 0.0) if stamp is None else stamp)
    texts = []
    for area, cx, cy in area_centroids(areas, graph):
        label = area.get("label")
        texts.append(
            fg.TextPrimitive(
                pose=_pose(cx, cy, 1.0),
                billboard=True,
                font_size=0.5,
                color=_color(class_rgba(label)),
                text=f"{label or '?'} #{area['id']}",
            )
        )
    entity = fg.SceneEntity(timestamp=when, frame_id=frame_id, id="areas", texts=texts)
    return fg.SceneUpdate(entities=[entity])


def people_scene(people: Mapping[str, Any], *, stamp: float | None = None) -> fg.SceneUpdate:
    """The people of a ``loci.people/1`` message as a SceneUpdate (entity ``people``): a
    cylinder per track with its id and an arrow of its velocity (one second ahead), a sphere
    per leg. ``frame_id`` and ``stamp`` default to the message's."""
    when = _stamp(people.get("stamp", 0.0) if stamp is None else stamp)
    color = _color(_PERSON_RGBA)
    d, h = PERSON_SIZE
    cylinders, texts, arrows, spheres = [], [], [], []
    for t in people.get("tracks", ()):
        x, y = float(t["x"]), float(t["y"])
        cylinders.append(
            fg.CylinderPrimitive(
                pose=_pose(x, y, h / 2),
                size=fg.Vector3(x=d, y=d, z=h),
                color=color,
                bottom_scale=1.0,
                top_scale=1.0,
            )
        )
        texts.append(
            fg.TextPrimitive(
                pose=_pose(x, y, h + 0.2), billboard=True, font_size=0.3, color=color, text=f"#{t['id']}"
            )
        )
        vx, vy = float(t.get("vx", 0.0)), float(t.get("vy", 0.0))
        speed = math.hypot(vx, vy)
        if speed > 0.05:
            yaw = math.atan2(vy, vx)
            q = fg.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
            arrows.append(
                fg.ArrowPrimitive(
                    pose=fg.Pose(position=fg.Vector3(x=x, y=y, z=0.1), orientation=q),
                    shaft_length=speed,
                    shaft_diameter=0.04,
                    head_length=0.15,
                    head_diameter=0.12,
                    color=color,
                )
            )
    for x, y in people.get("legs", ()):
        spheres.append(
            fg.SpherePrimitive(
                pose=_pose(float(x), float(y), 0.1),
                size=fg.Vector3(x=LEG_SIZE, y=LEG_SIZE, z=LEG_SIZE),
                color=color,
            )
        )
    entity = fg.SceneEntity(
        timestamp=when,
        frame_id=str(people.get("frame_id", "odom")),
        id="people",
        cylinders=cylinders,
        texts=texts,
        arrows=arrows,
        spheres=spheres,
    )
    return fg.SceneUpdate(entities=[entity])


_PARTICLE_RGBA = (0.1, 0.35, 0.85, 0.8)
_ESTIMATE_RGBA = (0.85, 0.1, 0.1, 1.0)


def localization_scene(
    particles: Any,
    pose: tuple[float, float, float],
    covariance: Any,
    *,
    stamp: float,
    frame_id: str = "map",
    max_particles: int = 2000,
) -> fg.SceneUpdate:
    """The particle filter as a SceneUpdate (entity ``localization``): each particle a short
    line along its heading (at most ``max_particles``, evenly picked), the estimate an arrow,
    its position covariance a 2σ ellipse (a line loop)."""
    import numpy as np

    P = np.asarray(particles, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] > max_particles:
        P = P[np.linspace(0, P.shape[0] - 1, max_particles).round().astype(int)]
    pts = []
    for x, y, th in P:
        pts.append(fg.Point3(x=float(x), y=float(y), z=0.05))
        pts.append(fg.Point3(x=float(x + 0.25 * math.cos(th)), y=float(y + 0.25 * math.sin(th)), z=0.05))
    lines = []
    if pts:
        lines.append(
            fg.LinePrimitive(
                type=fg.LinePrimitiveLineType.LineList,
                pose=_pose(0.0, 0.0),
                thickness=0.02,
                points=pts,
                color=_color(_PARTICLE_RGBA),
            )
        )
    C = np.asarray(covariance, dtype=np.float64).reshape(3, 3)[:2, :2]
    vals, vecs = np.linalg.eigh((C + C.T) / 2)
    radii = 2.0 * np.sqrt(np.maximum(vals, 0.0))
    ring = []
    for a in np.linspace(0, 2 * math.pi, 37)[:-1]:
        v = vecs @ (radii * np.array([math.cos(a), math.sin(a)]))
        ring.append(fg.Point3(x=float(pose[0] + v[0]), y=float(pose[1] + v[1]), z=0.06))
    lines.append(
        fg.LinePrimitive(
            type=fg.LinePrimitiveLineType.LineLoop,
            pose=_pose(0.0, 0.0),
            thickness=0.04,
            points=ring,
            color=_color(_ESTIMATE_RGBA),
        )
    )
    yaw = float(pose[2])
    arrow = fg.ArrowPrimitive(
        pose=fg.Pose(
            position=fg.Vector3(x=float(pose[0]), y=float(pose[1]), z=0.1),
            orientation=fg.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
        ),
        shaft_length=0.6,
        shaft_diameter=0.06,
        head_length=0.25,
        head_diameter=0.18,
        color=_color(_ESTIMATE_RGBA),
    )
    entity = fg.SceneEntity(
        timestamp=_stamp(stamp), frame_id=frame_id, id="localization", lines=lines, arrows=[arrow]
    )
    return fg.SceneUpdate(entities=[entity])
