"""The world of the guided tour (the book's Sect. 7.4): a small office built by hand.

Map frame: x right, y up, metres, origin at the lower-left corner of the map (the grid's
world frame). ``tour_world(0)`` lays out (numbers for seed 0; other seeds move the doors
and the furniture by a few decimetres)::

    y
    7.65 +-----------+---------------------+----------+---------+
         |           |           [couch]   |          |         |
         |  office   |table###  [B]      TV| kitchen  |  lab    |
         |           |    living room      |          |         |
    2.65 +----+ +----+-------+ +-----------+---+ +----+--+ +----+
         |                    corridor (20 m x 2 m)             |
    0.5  +--------[S]-------------------------------------------+
         0.5         6.5                  12.5               20.5  x

* a straight corridor, 20 m × 2 m, with the charging station ``[S]`` against its south wall
  3.5 m from the west end (:data:`STATION_X`) and the office's door behind it; the robot
  starts in front of the station, heading east along the corridor (a 12 m corridor closed
  at both ends is mostly "room" to the bundled place model, and so are its dead end and the
  places beside an open door; 20 m of plain corridor are corridor);
* a living room, 6 m × 5 m, behind a 0.85–0.95 m door in the corridor's north wall; in it
  a table standing against the west wall and a mop bucket ``[B]`` (a 0.5 m × 0.4 m box)
  0.78–0.92 m beyond the table's end, so that the gap between them is a narrow opening
  with "walls" (the table's long side, the bucket's flat side) continuing from both jambs:
  what :mod:`knowledge.navigation.doorways` takes for a door. A couch stands against the
  north wall and a television on a stand against the east wall;
* an office, a kitchen and a lab behind their own doors, which the tour does not enter.

The table is drawn **solid** in the grid (a table with a skirt, or boxes under it), not by
its legs as in the generated buildings: from its legs the detector would find no wall.

The tutor's walk comes in legs (:attr:`TourWorld.legs`), one per story step: into the
room through the real door; through the false doorway and round the bucket back to where
the robot already was (a loop that does not cross the real door again); to the room's
open east half, where the robot, following a metre behind, stops at the pose it looks
around from (:attr:`TourWorld.view_pose`: the couch and the television are both in view
there).

:class:`TourWorld` also carries the ground truth: the areas (rectangles with their class
and name), the real and the false doorway, and a :class:`~sim.buildings.Building`
record (labels, spaces, doors, furniture) so that the route planner, the pictures of
:mod:`sim.buildings_picture` and the simulated robot's ground truth work on
it as on a generated office.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from knowledge.labels import CLASS_NAMES, CORRIDOR, DOORWAY, ROOM
from knowledge.metric.grid import OccupancyGrid
from sim.buildings_doors import DOOR_ID_BASE
from sim.buildings_model import Building, Door, Furniture, Room, WorldRect
from sim.objects import WorldObject
from sim.world import SimWorld

__all__ = ["AreaTruth", "DoorwayTruth", "TourLeg", "TourWorld", "tour_world"]

Point = tuple[float, float]
Pose = tuple[float, float, float]

#: Metres per cell.
RESOLUTION = 0.05
#: Wall thickness, metres.
WALL = 0.15
#: Unknown margin around the outer walls, metres.
MARGIN = 0.35
#: How far behind the tutor the robot walks when it follows (metres, along the tutor's path).
FOLLOW_DISTANCE = 1.0
#: The mop bucket's footprint ``(width along the table's line, depth)``, metres.
BUCKET_SIZE = (0.5, 0.4)
#: The story's legs of the tutor's walk, in order.
LEG_NAMES = ("into_room", "false_doorway", "to_view")
#: x of the charging station (against the corridor's south wall) and of the robot's start, metres
STATION_X = 4.0

_SPACE_CORRIDOR, _SPACE_OFFICE, _SPACE_LIVING, _SPACE_KITCHEN, _SPACE_LAB = 1, 2, 3, 4, 5


@dataclass(frozen=True)
class TourLeg:
    """One leg of the tutor's walk.

    Attributes:
        name: one of :data:`LEG_NAMES`.
        waypoints: ``(x, y)`` map-frame metres; the first is where the previous leg ended
            (or the tutor's start).
        says: what the leg is for, for people.
    """

    name: str
    waypoints: tuple[Point, ...]
    says: str

    @property
    def length(self) -> float:
        """Metres along the leg."""
        w = np.asarray(self.waypoints)
        return float(np.hypot(*np.diff(w, axis=0).T).sum()) if len(w) > 1 else 0.0


@dataclass(frozen=True)
class AreaTruth:
    """A ground-truth area: a rectangle of the map with its place class and its name.

    Attributes:
        space: the space id (as in ``Building.spaces``).
        name: what people call it ("corridor", "living room", "office").
        label: its place class ("corridor", "room").
        rect: ``(x_min, y_min, x_max, y_max)`` metres, the free interior.
    """

    space: int
    name: str
    label: str
    rect: WorldRect

    @property
    def polygon(self) -> tuple[Point, ...]:
        """The rectangle's corners, counter-clockwise from the lower left."""
        x0, y0, x1, y1 = self.rect
        return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))

    def contains(self, xy: Sequence[float], margin: float = 0.0) -> bool:
        """Whether ``xy`` lies inside the rectangle grown by ``margin`` metres."""
        x0, y0, x1, y1 = self.rect
        return x0 - margin <= xy[0] <= x1 + margin and y0 - margin <= xy[1] <= y1 + margin


@dataclass(frozen=True)
class DoorwayTruth:
    """A narrow opening the robot passes: its centre, width and normal (map frame).

    Attributes:
        center: ``(x, y)`` metres, midway between the jambs.
        width: metres between the jambs.
        orientation: radians, the opening's normal (the way the tour passes it first).
        real: a door in a wall (True) or the gap between the table and the bucket (False).
    """

    center: Point
    width: float
    orientation: float
    real: bool


@dataclass(frozen=True, eq=False)
class TourWorld:
    """The tour's office, its objects, the tutor's walk and the ground truth.

    Attributes:
        building: the grid with labels, spaces, rooms, doors and furniture.
        objects: the pictures the camera sees (names: ``charging_station``, ``couch``,
            ``television``, ``table``, ``bucket``).
        start: the robot's start pose ``(x, y, heading)`` in front of the charging station.
        tutor_start: where the tutor stands when the tour begins (facing the robot's way).
        legs: the tutor's walk, one :class:`TourLeg` per story step (:data:`LEG_NAMES`).
        view_pose: the robot's pose at the end of the walk, from which it looks around.
        areas: the ground-truth areas.
        doorway: the real door into the living room.
        false_doorway: the gap between the table and the bucket.
        seed: the seed.
    """

    building: Building
    objects: tuple[WorldObject, ...]
    start: Pose
    tutor_start: Point
    legs: tuple[TourLeg, ...]
    view_pose: Pose
    areas: tuple[AreaTruth, ...]
    doorway: DoorwayTruth
    false_doorway: DoorwayTruth
    seed: int

    @property
    def grid(self) -> OccupancyGrid:
        return self.building.grid

    def world(self) -> SimWorld:
        """The grid and the objects, for the camera (:class:`~sim.camera_view.VirtualCamera`)."""
        return SimWorld(self.grid, self.objects)

    def leg(self, name: str) -> TourLeg:
        """The leg called ``name`` (KeyError naming the known ones)."""
        for leg in self.legs:
            if leg.name == name:
                return leg
        raise KeyError(f"no tour leg {name!r}; the legs are {[g.name for g in self.legs]}")

    def object(self, name: str) -> WorldObject:
        """The object called ``name`` (KeyError naming the known ones)."""
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(f"no object {name!r} in the tour world; known: {[o.name for o in self.objects]}")

    def tutor_path(self) -> np.ndarray:
        """``(k, 2)`` the tutor's whole walk: its start and every leg's waypoints, in order."""
        pts: list[Point] = [self.tutor_start]
        for leg in self.legs:
            pts.extend(leg.waypoints[1:] if leg.waypoints[0] == pts[-1] else leg.waypoints)
        return np.asarray(pts, dtype=np.float64)

    def follow_path(self, distance: float = FOLLOW_DISTANCE) -> np.ndarray:
        """``(k, 2)`` where a robot following the tutor drives: from its start along the
        tutor's path, ending ``distance`` metres short of the tutor's last point."""
        path = np.vstack([np.asarray(self.start[:2])[None, :], self.tutor_path()])
        return _trim_end(path, distance)

    def area_at(self, xy: Sequence[float], margin: float = 0.0) -> AreaTruth | None:
        """The ground-truth area holding ``xy`` (None: a wall, a door opening or outside)."""
        for a in self.areas:
            if a.contains(xy, margin):
                return a
        return None

    def label_at(self, xy: Sequence[float]) -> str | None:
        """The ground-truth place class at ``xy`` (``Building.labels``: doorways included)."""
        g = self.grid
        rc = g.world_to_cell(np.asarray(xy, dtype=np.float64))
        if not bool(g.in_bounds(rc)):
            return None
        return CLASS_NAMES.get(int(self.building.labels[rc[0], rc[1]]))

    def save_map(self, yaml_path: str | Path) -> Path:
        """Write the grid as a map_server map (YAML + PGM); returns the YAML path."""
        return self.grid.save(yaml_path)


# ------------------------------------------------------------------------------ building it
def tour_world(seed: int = 0) -> TourWorld:
    """The guided tour's office (see the module docstring).

    The seed moves the living room's door along the wall (±0.3 m), varies the doors' widths
    (0.85–0.95 m), the gap between the table and the bucket (0.78–0.92 m), the table's
    length and the television's place by small amounts; every seed gives a tour that works.

    Raises:
        ValueError: ``seed`` is not a non-negative integer.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    door_x = 9.5 + float(rng.uniform(-0.3, 0.3))
    widths = rng.uniform(0.85, 0.95, 4)
    # the office's door near the corridor's west end, behind the robot's start: the tour's
    # corridor nodes lie in the plain corridor (beside an open door or at the dead end the
    # bundled model often says "room")
    office_door_x = 1.6 + float(rng.uniform(-0.2, 0.2))
    gap = float(rng.uniform(0.78, 0.92))
    table_len = float(rng.uniform(1.3, 1.5))
    table_y = 5.2 + float(rng.uniform(-0.15, 0.15))
    tv_y = 5.0 + float(rng.uniform(-0.2, 0.2))

    corridor: WorldRect = (0.5, 0.5, 20.5, 2.5)
    y_rooms = corridor[3] + WALL
    top = y_rooms + 5.0
    wall_y = (corridor[3] + y_rooms) / 2
    # (id, use, rectangle, door centre x, door width); the living room is the tour's
    rooms = (
        (_SPACE_OFFICE, "office", (0.5, y_rooms, 6.35, top), office_door_x, float(widths[0])),
        (_SPACE_LIVING, "living room", (6.5, y_rooms, 12.5, top), door_x, float(widths[1])),
        (_SPACE_KITCHEN, "kitchen", (12.65, y_rooms, 16.5, top), 14.3, float(widths[2])),
        (_SPACE_LAB, "lab", (16.65, y_rooms, 20.5, top), 17.6, float(widths[3])),
    )
    living = rooms[1][2]

    # furniture: (kind, rectangle, shape, facing) — facing: the direction its front looks
    lx0, _, lx1, ly1 = living
    table = (lx0, table_y - 0.4, lx0 + table_len, table_y + 0.4)
    # a mop bucket on its trolley: a box, so that its side facing the table reads as a wall
    bucket_w, bucket_d = BUCKET_SIZE
    bucket_c = (table[2] + gap + bucket_w / 2, table_y)
    items: list[tuple[str, WorldRect, str, float]] = [
        (
            "charging_station",
            (STATION_X - 0.25, corridor[1], STATION_X + 0.25, corridor[1] + 0.3),
            "solid",
            math.pi / 2,
        ),
        ("table", table, "solid", math.pi / 2),
        (
            "bucket",
            (
                bucket_c[0] - bucket_w / 2,
                table_y - bucket_d / 2,
                bucket_c[0] + bucket_w / 2,
                table_y + bucket_d / 2,
            ),
            "solid",
            -math.pi / 2,
        ),
        ("couch", (lx1 - 2.3, ly1 - 0.9, lx1 - 0.3, ly1), "solid", -math.pi / 2),
        ("tv", (lx1 - 0.4, tv_y - 0.55, lx1, tv_y + 0.55), "solid", math.pi),
    ]

    H = top + WALL + MARGIN
    W = corridor[2] + WALL + MARGIN
    rows, cols = round(H / RESOLUTION), round(W / RESOLUTION)
    spaces = np.zeros((rows, cols), dtype=np.int32)

    def cells(r: WorldRect) -> tuple[slice, slice]:
        x0, y0, x1, y1 = r
        c0, c1 = round(x0 / RESOLUTION), round(x1 / RESOLUTION)
        r0, r1 = rows - round(y1 / RESOLUTION), rows - round(y0 / RESOLUTION)
        return slice(max(r0, 0), max(r1, 0)), slice(max(c0, 0), max(c1, 0))

    spaces[cells(corridor)] = _SPACE_CORRIDOR
    doors: list[Door] = []
    for i, (sid, _use, rect, x, w) in enumerate(rooms):
        spaces[cells(rect)] = sid
        did = DOOR_ID_BASE + i
        spaces[cells((x - w / 2, corridor[3], x + w / 2, y_rooms))] = did
        # orientation: from the room (connects[0]) into the corridor, as in generated buildings
        doors.append(Door(did, (x, wall_y), w, -math.pi / 2, (sid, _SPACE_CORRIDOR), WALL))
    outline = np.zeros_like(spaces, dtype=bool)
    outline[cells((corridor[0] - WALL, corridor[1] - WALL, corridor[2] + WALL, top + WALL))] = True

    # labels before furniture (it stands inside the spaces), doorways as in the IPA maps
    labels = np.zeros(spaces.shape, dtype=np.uint8)
    labels[spaces == _SPACE_CORRIDOR] = CORRIDOR
    labels[(spaces > _SPACE_CORRIDOR) & (spaces < DOOR_ID_BASE)] = ROOM
    for door in doors:
        x, half = door.center[0], door.width / 2 + 0.05
        labels[cells((x - half, corridor[3] - 0.3, x + half, y_rooms + 0.35))] = DOORWAY
    furniture: list[Furniture] = []
    for kind, rect, shape, facing in items:
        spaces[cells(rect)] = 0
        yaw = facing - math.pi / 2  # the records' yaw is the local x axis; the front is yaw + π/2
        w, d = rect[2] - rect[0], rect[3] - rect[1]
        along_x = math.isclose(abs(math.cos(yaw)), 1.0, abs_tol=1e-6)
        size = (w, d) if along_x else (d, w)
        room_id = _SPACE_CORRIDOR if kind == "charging_station" else _SPACE_LIVING
        furniture.append(
            Furniture(kind, ((rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2), size, yaw, room_id, shape)
        )
    labels[spaces == 0] = 0

    free = spaces > 0
    occupied = outline & ~free
    grid = OccupancyGrid.from_masks(occupied, RESOLUTION, unknown=~outline, name=f"tour_office_{seed}")
    labels.setflags(write=False)
    spaces.setflags(write=False)
    rooms_out = tuple(Room(sid, "room", use, (rect,), ROOM) for sid, use, rect, _x, _w in rooms)
    building = Building(
        grid=grid,
        labels=labels,
        spaces=spaces,
        rooms=rooms_out,
        corridors=(Room(_SPACE_CORRIDOR, "corridor", "corridor", (corridor,), CORRIDOR),),
        doors=tuple(doors),
        furniture=tuple(furniture),
        seed=int(seed),
        params={"tour_world": int(seed)},
    )

    objects = _pictures(furniture)
    start: Pose = (STATION_X, 1.5, 0.0)  # in front of the station, facing along the corridor
    tutor_start = (start[0] + 1.1, 1.5)
    mid_gap = (table[2] + gap / 2, table_y)
    inside = (door_x, y_rooms + 0.9)
    # the loop: west of the door to below the gap, north through it, east above the bucket,
    # south past the bucket's east side, back past the node inside the door and on along the
    # way in to beyond the point below the gap: the robot, 1 m behind, then drives over the
    # places it passed on the way in, so the loop round the bucket closes on known nodes
    below = (mid_gap[0], table[1] - 0.8)
    above = (mid_gap[0], table[3] + 0.7)
    east = bucket_c[0] + bucket_w / 2 + 0.85
    back = (door_x + 0.1, inside[1] + 0.1)
    beyond = (below[0] - 0.9, below[1] + 0.2)
    legs = (
        TourLeg(
            "into_room",
            (tutor_start, (door_x, 1.5), (door_x, wall_y), inside, below),
            "along the corridor and through the door into the room",
        ),
        TourLeg(
            "false_doorway",
            (below, above, (east, above[1]), (east, below[1]), back, below, beyond),
            "between the table and the bucket, round the bucket and back the way we came in",
        ),
        TourLeg(
            "to_view",
            (beyond, (lx1 - 1.0, inside[1] + 0.3)),
            "into the open half of the room, in front of the couch and the television",
        ),
    )
    areas = (
        AreaTruth(_SPACE_CORRIDOR, "corridor", "corridor", corridor),
        *(AreaTruth(sid, use, "room", rect) for sid, use, rect, _x, _w in rooms),
    )
    tw = TourWorld(
        building=building,
        objects=objects,
        start=start,
        tutor_start=tutor_start,
        legs=legs,
        view_pose=(0.0, 0.0, 0.0),
        areas=areas,
        doorway=DoorwayTruth((door_x, wall_y), float(widths[1]), math.pi / 2, True),
        false_doorway=DoorwayTruth(mid_gap, gap, math.pi / 2, False),
        seed=int(seed),
    )
    end = tw.follow_path()
    heading = math.atan2(*(end[-1] - end[-2])[::-1])
    view: Pose = (float(end[-1, 0]), float(end[-1, 1]), heading)
    return replace(tw, view_pose=view)


_PICTURE = {"tv": "television"}


def _pictures(furniture: Sequence[Furniture]) -> tuple[WorldObject, ...]:
    """One picture on the front face of each item, 5 cm in front of it, named by its kind."""
    out = []
    for f in furniture:
        kind = _PICTURE.get(f.kind, f.kind)
        face = f.yaw + math.pi / 2
        depth = f.size[1] / 2 + 0.05
        x, y = f.center[0] + depth * math.cos(face), f.center[1] + depth * math.sin(face)
        width = min(f.size[0], 2.0)
        out.append(WorldObject.place(kind, x, y, face, name=kind, width_m=width))
    return tuple(out)


def _trim_end(path: np.ndarray, distance: float) -> np.ndarray:
    """The polyline ``path`` ``(k, 2)`` without its last ``distance`` metres."""
    if distance <= 0:
        return path
    seg = np.hypot(*np.diff(path, axis=0).T)
    total = float(seg.sum())
    keep = max(0.0, total - distance)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    i = int(np.searchsorted(cum, keep, side="right") - 1)
    i = min(i, len(seg) - 1)
    f = (keep - cum[i]) / seg[i] if seg[i] > 0 else 0.0
    end = path[i] + f * (path[i + 1] - path[i])
    return np.vstack([path[: i + 1], end[None, :]])
