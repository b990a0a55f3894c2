"""The records of a generated building: rooms, doors, furniture and the building itself.

Coordinates are world metres in the grid's frame (x right, y up, origin at the lower-left
corner of the map); arrays are ``(rows, cols)`` in image orientation. See
:mod:`sim.buildings` for how they are made.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from knowledge.metric.grid import OccupancyGrid

WorldRect = tuple[float, float, float, float]


@dataclass(frozen=True)
class Room:
    """A room, hall or corridor.

    Attributes:
        id: space id (as in ``Building.spaces``).
        kind: "room", "hall" or "corridor".
        use: what it is used as ("office", "lab", "seminar", "kitchen", "storage",
            "living room", "hall", "corridor").
        rects: world rectangles ``(x_min, y_min, x_max, y_max)`` (metres) whose union is its
            free interior (one for rooms and halls, several for bent or ring corridors).
        label: its place label code (knowledge.labels).
    """

    id: int
    kind: str
    use: str
    rects: tuple[WorldRect, ...]
    label: int

    @property
    def rect(self) -> WorldRect:
        """Bounding box ``(x_min, y_min, x_max, y_max)`` in metres."""
        xs0, ys0, xs1, ys1 = zip(*self.rects, strict=True)
        return (min(xs0), min(ys0), max(xs1), max(ys1))

    @property
    def area(self) -> float:
        """Floor area in m² (furniture included)."""
        return sum((x1 - x0) * (y1 - y0) for x0, y0, x1, y1 in self.rects)

    @property
    def center(self) -> tuple[float, float]:
        """Centre of the bounding box (metres); inside the room for rooms and halls."""
        x0, y0, x1, y1 = self.rect
        return ((x0 + x1) / 2, (y0 + y1) / 2)


@dataclass(frozen=True)
class Door:
    """An opening through a wall.

    Attributes:
        id: door id (``>= DOOR_ID_BASE``; the opening's cells carry it in ``Building.spaces``).
        center: world ``(x, y)`` of the opening's centre (metres, mid-wall).
        width: clear width along the wall (metres).
        orientation: direction (rad) of the wall normal through the opening, pointing from
            ``connects[0]`` into ``connects[1]``.
        connects: ``(room, other)`` space ids: the room the door belongs to and the
            corridor, hall or room it opens into.
        wall_thickness: depth of the opening (metres).
    """

    id: int
    center: tuple[float, float]
    width: float
    orientation: float
    connects: tuple[int, int]
    wall_thickness: float


@dataclass(frozen=True)
class Furniture:
    """A piece of furniture.

    Attributes:
        kind: "table", "desk", "chair", "cabinet", "shelf", "counter", "fridge", "couch",
            "tv", "equipment", "printer", "plant", "pillar", "partition", "bucket",
            "charging_station".
        center: world ``(x, y)`` (metres).
        size: ``(w, d)`` metres: width along its local x axis, depth along its local y.
        yaw: angle (rad, counter-clockwise from world +x) of its local x axis; its front
            faces local +y, i.e. the direction ``yaw + π/2``, away from the wall it stands
            against (multiples of π/2: items are axis-aligned).
        room: the id of the space it stands in.
        shape: how it shows in the grid: "solid", "legs" (tables, desks) or "disk".
    """

    kind: str
    center: tuple[float, float]
    size: tuple[float, float]
    yaw: float
    room: int
    shape: str


@dataclass(frozen=True, eq=False)
class Building:
    """A generated office floor (see the module docstring for the array conventions).

    Attributes:
        grid: the occupancy grid.
        labels: ``(rows, cols)`` uint8 place codes, 0 on non-free cells.
        spaces: ``(rows, cols)`` int32 space ids (doors' opening cells: door ids), 0 on non-free cells.
        rooms: rooms and halls, by id.
        corridors: corridors, by id.
        doors: doors, by id.
        furniture: furniture in placement order.
        seed: the seed.
        params: every argument of :func:`generate_building`, resolved (``generate_building(**params)``
            rebuilds the same building).
    """

    grid: OccupancyGrid
    labels: np.ndarray
    spaces: np.ndarray
    rooms: tuple[Room, ...]
    corridors: tuple[Room, ...]
    doors: tuple[Door, ...]
    furniture: tuple[Furniture, ...]
    seed: int
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def halls(self) -> tuple[Room, ...]:
        return tuple(r for r in self.rooms if r.kind == "hall")

    def space(self, space_id: int) -> Room:
        """The room, hall or corridor with this id."""
        for r in (*self.corridors, *self.rooms):
            if r.id == space_id:
                return r
        raise KeyError(f"no space with id {space_id} (ids: corridors, halls and rooms of this building)")

    def door(self, door_id: int) -> Door:
        for d in self.doors:
            if d.id == door_id:
                return d
        raise KeyError(f"no door with id {door_id}")
