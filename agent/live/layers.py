"""Foxglove messages of the agent's layers, built from plain values (no I/O, no server).

* :func:`occupancy_grid` / :func:`label_grid`: ``foxglove.Grid`` of an
  :class:`~knowledge.metric.grid.OccupancyGrid` or of a label image, with ``red``,
  ``green``, ``blue``, ``alpha`` fields (the 3D panel's RGBA colour mode) and the cell's
  value (``occupancy``: 0 free, 100 occupied, -1 unknown; ``label``: the class code). A
  Grid's rows run from its pose's origin along +y, so the image-oriented arrays are flipped.
* :func:`transforms`: ``map → odom`` (identity until a localization provides one),
  ``odom → base_link`` (the robot's odometry pose) and ``base_link → laser`` (the mount).
* :func:`named_areas_scene`: each area's class, id and the names the conceptual map has
  for it (``kitchen``, ``LivingRoom``) over its nodes' centroid.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from foxglove import messages as fg

from agent.bus.scene import area_centroids, class_rgba
from knowledge.labels import CLASS_COLORS_BGR
from knowledge.metric.grid import FREE, OCCUPIED, OccupancyGrid

#: Frame names of the transforms (REP 105).
MAP, ODOM, BASE, LASER = "map", "odom", "base_link", "laser"

_OCC_RGBA = {FREE: (250, 250, 250, 200), OCCUPIED: (20, 20, 20, 255)}
_UNKNOWN_RGBA = (128, 128, 128, 60)


def timestamp(stamp: float) -> fg.Timestamp:
    """Seconds since the epoch as a Foxglove timestamp (negative or non-finite: 0)."""
    if not (math.isfinite(stamp) and stamp > 0):
        return fg.Timestamp(0, 0)
    sec = math.floor(stamp)
    nsec = min(999_999_999, round((stamp - sec) * 1e9))
    return fg.Timestamp(int(sec), int(nsec))


def _quat(yaw: float) -> fg.Quaternion:
    return fg.Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def _pose(x: float, y: float, yaw: float, z: float = 0.0) -> fg.Pose:
    return fg.Pose(position=fg.Vector3(x=x, y=y, z=z), orientation=_quat(yaw))


def _rgba_grid(
    rgba: np.ndarray, values: np.ndarray, value_name: str, resolution: float, origin: Sequence[float],
    stamp: float, frame_id: str,
) -> fg.Grid:  # fmt: skip
    """A Grid of ``(rows, cols, 4)`` uint8 colours and ``(rows, cols)`` int8 values, both in
    image orientation (row 0 at the top)."""
    rows, cols = values.shape
    cells = np.empty((rows, cols, 5), np.uint8)
    cells[..., :4] = rgba
    cells[..., 4] = values.astype(np.int8).view(np.uint8)
    data = np.ascontiguousarray(cells[::-1]).tobytes()
    u8, i8 = fg.PackedElementFieldNumericType.Uint8, fg.PackedElementFieldNumericType.Int8
    fields = [
        fg.PackedElementField(name=n, offset=i, type=u8)
        for i, n in enumerate(("red", "green", "blue", "alpha"))
    ]
    fields.append(fg.PackedElementField(name=value_name, offset=4, type=i8))
    ox, oy, yaw = (float(v) for v in origin)
    return fg.Grid(
        timestamp=timestamp(stamp),
        frame_id=frame_id,
        pose=_pose(ox, oy, yaw, z=-0.01),
        column_count=cols,
        cell_size=fg.Vector2(x=resolution, y=resolution),
        row_stride=cols * 5,
        cell_stride=5,
        fields=fields,
        data=data,
    )


def occupancy_grid(grid: OccupancyGrid, stamp: float, frame_id: str = ODOM) -> fg.Grid:
    """The occupancy grid as a ``foxglove.Grid``: free light, occupied black, unknown faint grey."""
    st = grid.state
    rgba = np.empty((*st.shape, 4), np.uint8)
    rgba[:] = _UNKNOWN_RGBA
    for value, colour in _OCC_RGBA.items():
        rgba[st == value] = colour
    return _rgba_grid(rgba, st, "occupancy", grid.resolution, grid.origin, stamp, frame_id)


def label_grid(
    labels: np.ndarray, resolution: float, origin: Sequence[float], stamp: float = 0.0, frame_id: str = MAP
) -> fg.Grid:
    """A label image (class codes, image orientation) as a ``foxglove.Grid`` in the class
    colours of the overlays; cells without a class are transparent."""
    codes = np.asarray(labels)
    rgba = np.zeros((*codes.shape, 4), np.uint8)
    for code, (b, g, r) in CLASS_COLORS_BGR.items():
        rgba[codes == code] = (r, g, b, 170)
    return _rgba_grid(rgba, np.minimum(codes, 127), "label", resolution, origin, stamp, frame_id)


def _transform(parent: str, child: str, x: float, y: float, yaw: float, stamp: float) -> fg.FrameTransform:
    return fg.FrameTransform(
        timestamp=timestamp(stamp),
        parent_frame_id=parent,
        child_frame_id=child,
        translation=fg.Vector3(x=x, y=y, z=0.0),
        rotation=_quat(yaw),
    )


def base_pose(
    laser: tuple[float, float, float], mount: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The robot's pose from the laser's pose and the laser's mount on the robot (``laser ⊖ mount``)."""
    lx, ly, lth = laser
    mx, my, myaw = mount
    th = lth - myaw
    c, s = math.cos(th), math.sin(th)
    return (lx - (c * mx - s * my), ly - (s * mx + c * my), math.atan2(math.sin(th), math.cos(th)))


def transforms(
    laser: tuple[float, float, float],
    mount: tuple[float, float, float],
    stamp: float,
    *,
    map_to_odom: tuple[float, float, float] = (0.0, 0.0, 0.0),
    laser_frame: str = LASER,
) -> fg.FrameTransforms:
    """``map → odom → base_link → laser`` at ``stamp`` for the laser's odometry-frame pose."""
    bx, by, bth = base_pose(laser, mount)
    return fg.FrameTransforms(
        transforms=[
            _transform(MAP, ODOM, *map_to_odom, stamp),
            _transform(ODOM, BASE, bx, by, bth, stamp),
            _transform(BASE, laser_frame, *mount, stamp),
        ]
    )


def area_names(concepts: Mapping[str, Any] | None) -> dict[int, list[str]]:
    """Area id → the names and types the conceptual map has for it (``loci.concepts/1`` snapshot)."""
    out: dict[int, list[str]] = {}
    for key, area in ((concepts or {}).get("areas") or {}).items():
        words = [str(n) for n in area.get("names", ())] + [str(t) for t in area.get("types", ())]
        if words:
            out[int(area.get("id", key))] = list(dict.fromkeys(words))
    return out


def named_areas_scene(
    areas: Mapping[str, Any],
    graph: Mapping[str, Any],
    names: Mapping[int, Sequence[str]] | None = None,
    *,
    frame_id: str = ODOM,
) -> fg.SceneUpdate:
    """Entity ``areas``: per area ``"<class> #<id>"`` and, below it, its names, over its nodes' centroid."""
    texts = []
    for area, cx, cy in area_centroids(areas, graph):
        label = area.get("label")
        r, g, b, a = class_rgba(label)
        text = f"{label or '?'} #{area['id']}"
        called = (names or {}).get(int(area["id"]))
        if called:
            text += "\n" + ", ".join(called)
        texts.append(
            fg.TextPrimitive(
                pose=_pose(cx, cy, 0.0, z=1.0),
                billboard=True,
                font_size=0.5,
                color=fg.Color(r=r, g=g, b=b, a=a),
                text=text,
            )
        )
    entity = fg.SceneEntity(
        timestamp=timestamp(float(areas.get("stamp", 0.0))), frame_id=frame_id, id="areas", texts=texts
    )
    return fg.SceneUpdate(entities=[entity])
