"""The simulated world: an occupancy grid (walls) plus the objects standing in it.

Geometry queries the simulated devices share: which points are blocked, ray casting along
the grid (for the camera's wall shading and occlusion) and line of sight. Occupied cells
and everything outside the grid block; free and unknown cells do not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import ndimage

from knowledge.errors import MapError
from knowledge.metric.grid import OccupancyGrid
from sim import WORLD_HELP
from sim.objects import WorldObject

if TYPE_CHECKING:
    from sim.buildings_model import Building
    from sim.tour import TourWorld

#: Ray marching samples a ray every this fraction of a cell.
_MARCH_STEP_CELLS = 1.0 / 3.0


@dataclass(frozen=True, eq=False)
class SimWorld:
    """An occupancy grid and the pictures standing in it.

    Attributes:
        grid: the walls (occupied cells), in the grid's world frame.
        objects: the objects; names must be unique and each must stand on a free cell.
    """

    grid: OccupancyGrid
    objects: tuple[WorldObject, ...] = ()
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        objs = tuple(self.objects)
        object.__setattr__(self, "objects", objs)
        names = [o.name for o in objs]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"object names must be unique; repeated: {sorted(dup)}")
        for o in objs:
            if self.blocked(np.array([o.x, o.y])):
                raise ValueError(
                    f"object {o.name} at ({o.x:.2f}, {o.y:.2f}) stands in a wall or outside the map; "
                    "move it onto a free cell (a few centimetres in front of the wall)"
                )

    def object(self, name: str) -> WorldObject:
        """The object called ``name`` (KeyError naming the known ones if absent)."""
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(f"no object {name!r} in the world; known: {[o.name for o in self.objects]}")

    def with_objects(self, *objects: WorldObject) -> SimWorld:
        """A new world with ``objects`` added."""
        return SimWorld(self.grid, self.objects + tuple(objects))

    # ------------------------------------------------------------------ geometry
    def blocked(self, xy: np.ndarray) -> np.ndarray:
        """Bool ``(...)``: world points ``(..., 2)`` in an occupied cell or outside the grid."""
        rc = self.grid.world_to_cell(np.asarray(xy, dtype=np.float64))
        inside = self.grid.in_bounds(rc)
        rows, cols = self.grid.shape
        r = np.clip(rc[..., 0], 0, rows - 1)
        c = np.clip(rc[..., 1], 0, cols - 1)
        return ~inside | self.grid.occupied[r, c]

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """Distance in metres from world points ``(..., 2)`` to the nearest occupied cell.

        Measured from the centre of the point's cell to the centre of the nearest occupied
        cell, less half a cell (so about the distance to that cell's face). 0 in occupied
        cells and outside the grid (the map edge counts as a wall).
        """
        if "clearance" not in self._cache:
            free = ~self.grid.occupied
            padded = np.pad(free, 1, constant_values=False)
            edt = ndimage.distance_transform_edt(padded)[1:-1, 1:-1]
            edt = np.maximum(edt - 0.5, 0.0) * self.grid.resolution
            self._cache["clearance"] = edt
        edt = self._cache["clearance"]
        rc = self.grid.world_to_cell(np.asarray(xy, dtype=np.float64))
        inside = self.grid.in_bounds(rc)
        rows, cols = self.grid.shape
        vals = edt[np.clip(rc[..., 0], 0, rows - 1), np.clip(rc[..., 1], 0, cols - 1)]
        return np.where(inside, vals, 0.0)

    def raycast(self, x: float, y: float, angles: np.ndarray, max_range: float) -> np.ndarray:
        """Distance (m) from ``(x, y)`` along world ``angles`` ``(n,)`` to the first occupied cell.

        ``inf`` where a ray leaves the grid or goes beyond ``max_range`` without a hit. Rays
        are marched every third of a cell and the hit refined to the face entered, so
        distances are exact for the cell found, but a ray can slip between two occupied cells
        that touch only at a corner.
        """
        return self.raycast_faces(x, y, angles, max_range)[0]

    def raycast_faces(
        self, x: float, y: float, angles: np.ndarray, max_range: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`raycast` plus, per ray, whether the face hit runs along the map's y axis
        (the ray entered the occupied cell through its left or right side)."""
        ang = np.asarray(angles, dtype=np.float64).ravel()
        step = self.grid.resolution * _MARCH_STEP_CELLS
        t = np.arange(0, math.ceil(max_range / step) + 1) * step
        px = x + np.cos(ang)[:, None] * t[None, :]
        py = y + np.sin(ang)[:, None] * t[None, :]
        rcf = self.grid.world_to_cell_float(np.stack([px, py], axis=-1))
        rc = np.floor(rcf).astype(np.int64)
        inside = self.grid.in_bounds(rc)
        rows, cols = self.grid.shape
        occ = self.grid.occupied[np.clip(rc[..., 0], 0, rows - 1), np.clip(rc[..., 1], 0, cols - 1)]
        # a ray that leaves the (convex) grid never comes back: cut it at the first outside sample
        left = np.cumsum(~inside, axis=1) > 0
        hit = occ & ~left
        hit[:, 0] = False  # the start point itself does not count
        first = np.argmax(hit, axis=1)
        idx = np.arange(len(ang))
        any_hit = hit[idx, first]
        prev = np.maximum(first - 1, 0)
        # refine to the face entered between the last free sample and the first occupied one:
        # the ray crossed a row boundary, a column boundary, or both (then it passed through an
        # intermediate cell, and if that one is occupied the first crossing was the entry)
        a, b = rcf[idx, prev], rcf[idx, first]
        ca, cb = rc[idx, prev], rc[idx, first]
        moved = ca != cb  # (n, 2): row moved, column moved
        line = np.maximum(ca, cb).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(moved, np.clip((line - a) / (b - a), 0.0, 1.0), np.nan)
        f_row, f_col = frac[:, 0], frac[:, 1]
        both = moved[:, 0] & moved[:, 1]
        col_first = f_col < f_row
        inter = np.where(
            col_first[:, None], np.stack([ca[:, 0], cb[:, 1]], 1), np.stack([cb[:, 0], ca[:, 1]], 1)
        )
        inter_occ = self.grid.occupied[np.clip(inter[:, 0], 0, rows - 1), np.clip(inter[:, 1], 0, cols - 1)]
        first_f = np.fmin(f_row, f_col)
        last_f = np.fmax(f_row, f_col)
        entry = np.where(both & ~inter_occ, last_f, np.where(both, first_f, np.fmax(f_row, f_col)))
        side = np.where(both, col_first == inter_occ, moved[:, 1])
        entry = np.nan_to_num(entry, nan=1.0)
        dist = np.where(any_hit, t[prev] + entry * step, np.inf)
        return dist, side & any_hit

    def line_of_sight(self, a: np.ndarray, b: np.ndarray) -> bool:
        """True when the segment between world points ``a`` and ``b`` crosses no occupied cell.

        The end points themselves are not tested (a picture stands against its wall).
        """
        pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        length = float(np.hypot(*(pb - pa)))
        n = max(2, math.ceil(length / (self.grid.resolution * _MARCH_STEP_CELLS)))
        s = np.linspace(0.0, 1.0, n + 1)[1:-1]
        pts = pa[None, :] + s[:, None] * (pb - pa)[None, :]
        return not bool(self.blocked(pts).any())


# ------------------------------------------------------------------------------ a demo world
def demo_world(resolution: float = 0.05) -> SimWorld:
    """A 12 m × 8 m flat for demos and tests: a corridor along the bottom (y < 2 m) and three
    rooms above it — living room (x < 6), kitchen (6–9) and office (9–12) — each with a
    doorway to the corridor, and objects: a charging station in the corridor; couch,
    television and bookcase in the living room; fridge and coffee machine in the kitchen;
    desk, monitor and whiteboard in the office. Origin (0, 0) at the lower-left corner.
    """
    w_m, h_m, wall = 12.0, 8.0, 0.1
    cols, rows = round(w_m / resolution), round(h_m / resolution)
    occ = np.zeros((rows, cols), dtype=bool)

    def box(x0: float, y0: float, x1: float, y1: float, value: bool = True) -> None:
        # world rectangle → image rows (row 0 at the top, y up)
        c0, c1 = round(x0 / resolution), round(x1 / resolution)
        r0, r1 = rows - round(y1 / resolution), rows - round(y0 / resolution)
        occ[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = value

    box(0, 0, w_m, wall)
    box(0, h_m - wall, w_m, h_m)
    box(0, 0, wall, h_m)
    box(w_m - wall, 0, w_m, h_m)
    box(0, 2.0, w_m, 2.0 + wall)  # corridor / rooms
    box(6.0, 2.0, 6.0 + wall, h_m)
    box(9.0, 2.0, 9.0 + wall, h_m)
    for x0 in (2.5, 7.0, 10.0):  # doorways, 0.9 m wide
        box(x0, 2.0, x0 + 0.9, 2.0 + wall, value=False)
    grid = OccupancyGrid.from_masks(occ, resolution, name="demo_flat")
    half_pi = math.pi / 2
    objects = (
        WorldObject.place("charging_station", 1.2, 0.2, half_pi, name="charging_station"),
        WorldObject.place("couch", 2.5, 7.75, -half_pi, name="couch"),
        WorldObject.place("television", 0.25, 5.0, 0.0, name="television"),
        WorldObject.place("bookcase", 5.85, 5.2, math.pi, name="bookcase"),
        WorldObject.place("fridge", 7.2, 7.75, -half_pi, name="fridge"),
        WorldObject.place("coffee_machine", 8.85, 5.0, math.pi, name="coffee_machine"),
        WorldObject.place("desk", 10.6, 7.75, -half_pi, name="desk"),
        WorldObject.place("monitor", 10.6, 7.6, -half_pi, name="monitor"),
        WorldObject.place("whiteboard", 11.85, 5.0, math.pi, name="whiteboard"),
    )
    return SimWorld(grid, objects)


# ---------------------------------------------------------------------------- --world


def load_tour(spec: str | None) -> TourWorld | None:
    """The guided tour's world of a ``demo:SEED`` specification (None for other worlds).

    Raises:
        MapError: ``demo:`` is not followed by a seed.
    """
    if not spec or not spec.startswith("demo:"):
        return None
    from sim.tour import tour_world

    try:
        seed = int(spec[len("demo:") :])
    except ValueError:
        raise MapError(f"world {spec}: after 'demo:' comes a seed, e.g. demo:0") from None
    if seed < 0:
        raise MapError(f"world {spec}: the seed must be >= 0")
    return tour_world(seed)


def load_world(spec: str | None, resolution: float | None = None) -> tuple[OccupancyGrid, Building | None]:
    """The grid (and the building, when generated) of a world specification: one syntax for
    every simulator command (:data:`WORLD_HELP`; None is ``gen:0``).

    Raises:
        MapError: a malformed seed, or no such map file.
    """
    from sim.buildings import generate_building, generate_tour_office

    spec = spec or "gen:0"
    tour = load_tour(spec)
    if tour is not None:
        return tour.grid, tour.building
    for prefix, make in (("gen:", generate_building), ("tour:", generate_tour_office)):
        if spec.startswith(prefix):
            try:
                seed = int(spec[len(prefix) :])
            except ValueError:
                raise MapError(f"world {spec}: after {prefix!r} comes a seed, e.g. {prefix}7") from None
            building = make(seed)
            return building.grid, building
    path = Path(spec)
    if not path.exists():
        raise MapError(f"world {spec}: no such map file (give {WORLD_HELP})")
    return OccupancyGrid.load(path, resolution), None
