"""Procedural office floors with per-cell place labels: training data, test fixtures, simulator worlds.

``generate_building(seed)`` draws a floor plan (a straight, L, T or ring corridor, optional
open halls), cuts its strips into rooms of 2.5–12 m × 3–8 m, connects every room by a door
to a corridor, a hall or an already connected neighbour, furnishes the rooms and rasterises
everything into an :class:`~knowledge.metric.grid.OccupancyGrid` with a label image and a
ground-truth room segmentation. The same seed and options give identical arrays.

Conventions
-----------
* Arrays are ``(rows, cols)`` in image orientation (row 0 at the top), like the grid. The
  world frame is the grid's: x right, y up, metres, origin at the lower-left map corner.
* Grid: walls and furniture are occupied; the free interior is free; everything outside the
  outer walls is *unknown* (``outside="unknown"``, the default, as in a real SLAM map) or
  occupied (``outside="occupied"``, as in the IPA labelled maps).
* ``labels``: :mod:`knowledge.labels` codes, ROOM, CORRIDOR, HALLWAY (open halls) and
  DOORWAY on every free cell, 0 elsewhere. Doorways are painted as in the IPA labelled maps:
  a rectangle across the opening (see :mod:`sim.buildings_doors`).
* ``spaces``: the id of the room, corridor or hall each free cell belongs to, 0 on occupied
  and outside cells. The cells *inside a door opening* (within the wall thickness) carry the
  door's id, ``>= DOOR_ID_BASE`` (10000); the doorway label's overhang into the rooms keeps
  the room's id. ``spaces`` is thus a room segmentation whose doors are closed by their own
  small regions, like the IPA ground truth closes them with a line.
* Space ids run 1, 2, ... over corridors, then halls, then rooms. A corridor is one space
  per connected corridor (a ring is one space); a hall splitting corridors makes several.
* Tables and desks occupy only their legs in the grid (see
  :mod:`sim.buildings_furniture`); the :class:`Furniture` records keep their
  full size for a simulator's collision model.

No imperfections are added: the real labelled maps this data is compared against are clean
drawn maps (straight walls, no holes), so noise would only widen the gap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from knowledge.labels import CORRIDOR, DOORWAY, HALLWAY, ROOM
from knowledge.metric.grid import OccupancyGrid
from sim.buildings_doors import DOOR_ID_BASE, DOOR_MAX_WIDTH, DOOR_MIN_WIDTH, DoorCut, DoorPlacer
from sim.buildings_furniture import (
    SHAPES,
    Furnisher,
    Item,
    assign_uses,
    furnish_building,
    living_room_candidates,
)
from sim.buildings_layout import (
    CORRIDOR_MAX_WIDTH,
    CORRIDOR_MIN_WIDTH,
    LAYOUTS,
    Dims,
    Rect,
    build_plan,
    partition_strip,
    sample_dims,
)
from sim.buildings_model import Building, Door, Furniture, Room, WorldRect
from sim.buildings_picture import label_building_png

__all__ = [
    "DOOR_ID_BASE",
    "LAYOUTS",
    "Building",
    "Door",
    "Furniture",
    "Room",
    "generate_building",
    "generate_tour_office",
    "label_building_png",
]

_DEFAULTS: dict[str, Any] = {
    "hall": None,
    "corridor_width": None,
    "door_width": None,
    "furniture_density": 1.0,
    "inner_doors": 0.15,
    "split_rooms": 0.15,
    "table_legs": True,
    "living_room": False,
    "charging_station": False,
    "bucket": False,
    "outside": "unknown",
}


def _check_options(
    seed: int, resolution: float, layout: str | None, options: dict[str, Any]
) -> dict[str, Any]:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if not (isinstance(resolution, (int, float)) and 0.02 <= resolution <= 0.2):
        raise ValueError(f"resolution must be 0.02–0.2 metres per cell (0.05 is usual), got {resolution!r}")
    if layout is not None and layout not in LAYOUTS:
        raise ValueError(
            f"unknown layout {layout!r}; choose one of {', '.join(LAYOUTS)} or None (from the seed)"
        )
    unknown = sorted(set(options) - set(_DEFAULTS))
    if unknown:
        raise ValueError(
            f"unknown option(s) {', '.join(unknown)}; generate_building knows {', '.join(_DEFAULTS)} "
            "(see help(generate_building))"
        )
    o = {**_DEFAULTS, **options}
    cw, dw = o["corridor_width"], o["door_width"]
    if cw is not None and not CORRIDOR_MIN_WIDTH <= cw <= CORRIDOR_MAX_WIDTH:
        raise ValueError(f"corridor_width must be {CORRIDOR_MIN_WIDTH}–{CORRIDOR_MAX_WIDTH} m, got {cw}")
    if dw is not None and not DOOR_MIN_WIDTH <= dw <= DOOR_MAX_WIDTH:
        raise ValueError(f"door_width must be {DOOR_MIN_WIDTH}–{DOOR_MAX_WIDTH} m, got {dw}")
    if not 0.0 <= o["furniture_density"] <= 3.0:
        raise ValueError(f"furniture_density must be 0–3, got {o['furniture_density']}")
    for key in ("inner_doors", "split_rooms"):
        if not 0.0 <= o[key] <= 1.0:
            raise ValueError(f"{key} is a probability (0–1), got {o[key]}")
    if o["outside"] not in ("unknown", "occupied"):
        raise ValueError(f'outside must be "unknown" or "occupied", got {o["outside"]!r}')
    return o


def generate_building(
    seed: int,
    *,
    resolution: float = 0.05,
    layout: str | None = None,
    furniture: bool = True,
    **options: Any,
) -> Building:
    """Generate one office floor (see the module docstring).

    Args:
        seed: non-negative integer; everything follows from it and the options.
        resolution: metres per cell (0.02–0.2).
        layout: "straight", "L", "T" or "loop"; None draws one from the seed.
        furniture: clutter the rooms, halls and corridors (the items asked for by
            ``living_room``, ``charging_station`` and ``bucket`` are placed either way).
        **options: (unknown keys raise ValueError)

            - ``hall`` (bool | None): an open hall (label HALLWAY) where corridors meet or
              at a corridor's end; None draws it from the seed (p = 0.35).
            - ``corridor_width`` (float | None): metres, 1.5–3.0; None draws it.
            - ``door_width`` (float | None): the building's typical door, 0.8–1.2 m (each
              door varies around it, bigger rooms get wider doors); None draws it.
            - ``furniture_density`` (float, 1.0): clutter scale, 0 (none) to 3.
            - ``inner_doors`` (float, 0.15): probability of an extra door between two
              neighbouring rooms (rooms without a corridor always get one).
            - ``split_rooms`` (float, 0.15): probability that a deep room is split into a
              front room and a back room reached through it.
            - ``table_legs`` (bool, True): tables and desks occupy only their legs.
            - ``living_room`` (bool, False): one room becomes a living room with a couch,
              a TV and a coffee table.
            - ``charging_station`` (bool, False): a charging station against a corridor wall.
            - ``bucket`` (bool, False): a bucket beside a table.
            - ``outside`` (str, "unknown"): "unknown" or "occupied" for the cells outside
              the outer walls.

    The layout, the doors and the furniture draw from separate random streams, so e.g.
    ``furniture=False`` gives the same walls and doors as ``furniture=True``. A room that no
    door can reach (very rare) is left out as a closed block; space ids then skip its id.

    Raises:
        ValueError: a bad argument (the message says which and what is allowed).
        RuntimeError: a requested living room, charging station or bucket found no place.
    """
    o = _check_options(seed, resolution, layout, options)
    seed = int(seed)
    res = float(resolution)
    rng_layout, rng_doors, rng_furn = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)
    )
    # draw every choice even when the caller fixed it, so params regenerate the same building
    drawn_layout = LAYOUTS[int(rng_layout.choice(len(LAYOUTS), p=[0.3, 0.2, 0.25, 0.25]))]
    drawn_hall = bool(rng_layout.random() < 0.35)
    drawn_cw = float(rng_layout.uniform(CORRIDOR_MIN_WIDTH, CORRIDOR_MAX_WIDTH))
    drawn_dw = float(rng_doors.uniform(0.85, 1.0))
    layout = layout if layout is not None else drawn_layout
    hall = bool(o["hall"]) if o["hall"] is not None else drawn_hall
    cw = float(o["corridor_width"]) if o["corridor_width"] is not None else drawn_cw
    dw = float(o["door_width"]) if o["door_width"] is not None else drawn_dw
    params: dict[str, Any] = {
        "seed": seed,
        "resolution": res,
        "layout": layout,
        "furniture": bool(furniture),
        **o,
        "hall": hall,
        "corridor_width": cw,
        "door_width": dw,
    }

    dims = sample_dims(rng_layout, res, cw)
    plan = build_plan(rng_layout, layout, dims, hall)
    room_rects = [
        r for s in plan.strips for r in partition_strip(rng_layout, s, dims, float(o["split_rooms"]))
    ]

    # ids: corridors, halls, rooms
    kinds: dict[int, str] = {}
    rects: dict[int, tuple[Rect, ...]] = {}
    for group, kind in (
        (plan.corridors, "corridor"),
        ([(h,) for h in plan.halls], "hall"),
        ([(r,) for r in room_rects], "room"),
    ):
        for rs in group:
            sid = len(kinds) + 1
            kinds[sid], rects[sid] = kind, tuple(rs)
    spaces, shift = _paint(rects, dims)
    rects = {sid: tuple(r.shift(*shift) for r in rs) for sid, rs in rects.items()}
    _check_walls(spaces, kinds)

    rooms = {sid: rs[0] for sid, rs in rects.items() if kinds[sid] == "room"}
    open_ids = {sid for sid, k in kinds.items() if k != "room"}
    placer = DoorPlacer(rng_doors, spaces, rooms, open_ids, dims, dw)
    for sid in placer.place_all(float(o["inner_doors"])):
        # a room no door could reach stays a closed block (a shaft or a stairwell)
        spaces[spaces == sid] = 0
        del kinds[sid], rects[sid], rooms[sid]
    doors = placer.doors
    keepout = np.zeros(spaces.shape, dtype=bool)
    for dc in doors:
        spaces[dc.opening.y0 : dc.opening.y1, dc.opening.x0 : dc.opening.x1] = dc.id
        k = dc.keepout
        keepout[max(k.y0, 0) : k.y1, max(k.x0, 0) : k.x1] = True

    uses = assign_uses(rng_furn, rooms, res)
    near = {dc.room for dc in doors if dc.target in open_ids}
    items = Furnisher(rng_furn, spaces, keepout, dims, bool(o["table_legs"]))
    furnish_building(
        items,
        rects,
        kinds,
        uses,
        clutter=bool(furniture),
        density=float(o["furniture_density"]),
        living=living_room_candidates(rooms, res, near) if o["living_room"] else None,
        charging_station=bool(o["charging_station"]),
        bucket=bool(o["bucket"]),
    )
    # the building's outline comes from the spaces before furniture, which stands inside them
    kernel = np.ones((2 * dims.outer_wall + 1,) * 2, np.uint8)
    inside = cv2.dilate((spaces > 0).astype(np.uint8), kernel) > 0
    spaces[items.mask] = 0

    free = spaces > 0
    labels = _label(spaces, kinds, doors)
    n, _ = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    if n != 2:
        raise RuntimeError(f"generator bug: seed {seed} gave {n - 1} separate free regions (expected one)")
    occupied, unknown = (~free & inside, ~inside) if o["outside"] == "unknown" else (~free, None)
    grid = OccupancyGrid.from_masks(occupied, res, unknown=unknown, name=f"building_{layout}_{seed}")
    rows = spaces.shape[0]
    world = _World(rows, res)
    rooms_out = tuple(
        Room(
            sid,
            kinds[sid],
            uses.get(sid, "hall"),
            tuple(world.rect(r) for r in rects[sid]),
            _LABEL_OF[kinds[sid]],
        )
        for sid in sorted(kinds)
        if kinds[sid] != "corridor"
    )
    corridors_out = tuple(
        Room(sid, "corridor", "corridor", tuple(world.rect(r) for r in rects[sid]), CORRIDOR)
        for sid in sorted(kinds)
        if kinds[sid] == "corridor"
    )
    labels.setflags(write=False)
    spaces.setflags(write=False)
    return Building(
        grid=grid,
        labels=labels,
        spaces=spaces,
        rooms=rooms_out,
        corridors=corridors_out,
        doors=tuple(world.door(dc) for dc in doors),
        furniture=tuple(world.item(it) for it in items.items),
        seed=seed,
        params=params,
    )


def generate_tour_office(seed: int, **options: Any) -> Building:
    """An office for the guided-tour demo: corridor, rooms, a living room with a couch and a TV,
    a charging station in the corridor and a bucket beside a table."""
    kw: dict[str, Any] = {"living_room": True, "charging_station": True, "bucket": True, **options}
    return generate_building(seed, **kw)


_LABEL_OF = {"room": ROOM, "corridor": CORRIDOR, "hall": HALLWAY}


def _paint(rects: dict[int, tuple[Rect, ...]], d: Dims) -> tuple[np.ndarray, tuple[int, int]]:
    """Rasterise the spaces into a fresh ``(rows, cols)`` int32 id array with a margin.

    Returns the array and the ``(dx, dy)`` shift from plan to raster cells.
    """
    allr = [r for rs in rects.values() for r in rs]
    x0, y0 = min(r.x0 for r in allr), min(r.y0 for r in allr)
    x1, y1 = max(r.x1 for r in allr), max(r.y1 for r in allr)
    m = d.outer_wall + d.cells(0.5)
    shift = (m - x0, m - y0)
    spaces = np.zeros((y1 - y0 + 2 * m, x1 - x0 + 2 * m), dtype=np.int32)
    for sid, rs in rects.items():
        for r in rs:
            s = r.shift(*shift)
            view = spaces[s.y0 : s.y1, s.x0 : s.x1]
            if (view != 0).any():
                raise RuntimeError(f"generator bug: space {sid} overlaps space {int(view.max())}")
            view[...] = sid
    return spaces, shift


def _check_walls(spaces: np.ndarray, kinds: dict[int, str]) -> None:
    """Only corridors and halls may touch without a wall between them."""
    is_open = np.zeros(int(spaces.max()) + 1, dtype=bool)
    for sid, k in kinds.items():
        is_open[sid] = k != "room"
    for a, b in ((spaces[:, :-1], spaces[:, 1:]), (spaces[:-1, :], spaces[1:, :])):
        touch = (a != b) & (a != 0) & (b != 0)
        bad = touch & ~(is_open[a] & is_open[b])
        if bad.any():
            i = np.flatnonzero(bad)[0]
            raise RuntimeError(f"generator bug: spaces {a.flat[i]} and {b.flat[i]} touch without a wall")


def _label(spaces: np.ndarray, kinds: dict[int, str], doors: list[DoorCut]) -> np.ndarray:
    """Place codes for every free cell: the space's class, then the doorway rectangles."""
    lut = np.zeros(DOOR_ID_BASE + len(doors) + 1, dtype=np.uint8)
    for sid, k in kinds.items():
        lut[sid] = _LABEL_OF[k]
    lut[DOOR_ID_BASE:] = DOORWAY
    labels = lut[spaces]
    H, W = spaces.shape
    for dc in doors:
        r = dc.label
        ys, xs = slice(max(r.y0, 0), min(r.y1, H)), slice(max(r.x0, 0), min(r.x1, W))
        sub = spaces[ys, xs]
        mine = (sub == dc.room) | (sub == dc.target) | (sub == dc.id)
        labels[ys, xs][mine] = DOORWAY
    return labels


_SIDE_NORMAL = {"top": math.pi / 2, "bottom": -math.pi / 2, "left": math.pi, "right": 0.0}


@dataclass(frozen=True)
class _World:
    """Cell rectangles → world metres for a raster of ``rows`` rows (origin at the lower left)."""

    rows: int
    res: float

    def rect(self, r: Rect) -> WorldRect:
        s = self.res
        return (r.x0 * s, (self.rows - r.y1) * s, r.x1 * s, (self.rows - r.y0) * s)

    def center(self, r: Rect) -> tuple[float, float]:
        x0, y0, x1, y1 = self.rect(r)
        return ((x0 + x1) / 2, (y0 + y1) / 2)

    def door(self, dc: DoorCut) -> Door:
        return Door(
            id=dc.id,
            center=self.center(dc.opening),
            width=dc.width * self.res,
            orientation=_SIDE_NORMAL[dc.side],
            connects=(dc.room, dc.target),
            wall_thickness=dc.gap * self.res,
        )

    def item(self, it: Item) -> Furniture:
        w, h = it.rect.w * self.res, it.rect.h * self.res
        along_x = math.isclose(abs(math.cos(it.yaw)), 1.0, abs_tol=1e-6)
        return Furniture(
            kind=it.kind,
            center=self.center(it.rect),
            size=(w, h) if along_x else (h, w),
            yaw=it.yaw,
            room=it.space,
            shape=SHAPES.get(it.kind, "solid"),
        )
