"""Collision-free routes for the simulated base: through door centres and along corridor axes.

:class:`RoutePlanner` plans on a lattice of points ``step`` metres apart over the free cells
of an occupancy grid that keep at least ``clearance`` metres from every non-free cell (walls,
furniture, unknown space). Moving along the lattice costs more near obstacles (up to
``prefer`` metres away), so shortest paths keep to the middle: along corridor axes, through
the middle of openings, between furniture. A planned path is then straightened (string
pulling): a corner is dropped when the straight segment that replaces it keeps as much
clearance as the part of the path it replaces (capped at ``prefer``), so straightening never
brings the route nearer to a wall than the lattice path was.

In a generated building (:meth:`RoutePlanner.for_building`) the route also crosses every
door it passes *along the door's normal, through its centre*: three fixed waypoints, one
``door_approach`` metres before the wall face, the door centre, one ``door_approach`` metres
beyond the other face, which straightening keeps.

A :class:`Route` holds the corners; :meth:`Route.dense` resamples it every ``spacing`` metres,
which is what :class:`~drivers.sim.base.SimBase` should follow (its pure-pursuit arcs to far
waypoints would bulge away from the straight segments).

Units: metres and radians in the grid's world frame; point arrays are ``(k, 2)`` ``(x, y)``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from knowledge.errors import MapError
from knowledge.metric.grid import OccupancyGrid
from sim.buildings import DOOR_ID_BASE, Building, Door

Point = tuple[float, float]
XY = Sequence[float] | np.ndarray

#: Cost per metre on the lattice is ``1 + _CENTRE_WEIGHT * max(0, prefer - clearance)²``.
_CENTRE_WEIGHT = 6.0


@dataclass(frozen=True)
class RouteParams:
    """How routes are planned.

    Attributes:
        step: lattice spacing, metres.
        clearance: least distance (metres) from a lattice point to any non-free cell; the
            base's radius plus a margin.
        prefer: clearance (metres) up to which the cost pushes paths away from obstacles,
            and which straightened segments keep where the lattice path had it.
        door_approach: metres before and beyond a door's wall faces where the route runs
            along the door's normal.
        spacing: default waypoint spacing of :meth:`Route.dense`, metres.
    """

    step: float = 0.1
    clearance: float = 0.3
    prefer: float = 1.0
    door_approach: float = 0.4
    spacing: float = 0.3

    def __post_init__(self) -> None:
        for name in ("step", "clearance", "prefer", "spacing"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"RouteParams.{name} must be a positive number of metres, got {v!r}")
        if not (math.isfinite(self.door_approach) and self.door_approach >= 0):
            raise ValueError(f"RouteParams.door_approach must be >= 0 metres, got {self.door_approach!r}")


@dataclass(frozen=True, eq=False)
class Route:
    """A planned route.

    Attributes:
        waypoints: ``(k, 2)`` corners, the start first (k >= 1).
        visits: ids of the spaces a tour visits, in order (empty for plain paths).
        doors: ids of the doors the route passes, in order.
        spacing: default spacing of :meth:`dense`, metres.
    """

    waypoints: np.ndarray
    visits: tuple[int, ...] = ()
    doors: tuple[int, ...] = ()
    spacing: float = 0.3

    def __post_init__(self) -> None:
        w = np.asarray(self.waypoints, dtype=np.float64).reshape(-1, 2)
        if w.shape[0] == 0 or not np.isfinite(w).all():
            raise ValueError("a route needs at least one finite (x, y) waypoint")
        w = np.array(w, copy=True)
        w.setflags(write=False)
        object.__setattr__(self, "waypoints", w)

    @property
    def length(self) -> float:
        """Length of the polyline, metres."""
        return float(np.hypot(*np.diff(self.waypoints, axis=0).T).sum()) if len(self.waypoints) > 1 else 0.0

    @property
    def start(self) -> Point:
        return (float(self.waypoints[0, 0]), float(self.waypoints[0, 1]))

    @property
    def start_heading(self) -> float:
        """Direction (radians) of the first segment (0 for a one-point route)."""
        w = self.waypoints
        for k in range(1, len(w)):
            d = w[k] - w[0]
            if math.hypot(d[0], d[1]) > 1e-9:
                return math.atan2(d[1], d[0])
        return 0.0

    @property
    def closed(self) -> bool:
        """True when the route ends where it starts (it can be driven in a loop)."""
        return len(self.waypoints) > 2 and bool(np.hypot(*(self.waypoints[-1] - self.waypoints[0])) < 1e-6)

    def dense(self, spacing: float | None = None) -> np.ndarray:
        """``(m, 2)`` points along the route at most ``spacing`` metres apart, corners kept."""
        s = self.spacing if spacing is None else spacing
        if not (math.isfinite(s) and s > 0):
            raise ValueError(f"spacing must be a positive number of metres, got {s!r}")
        return resample(self.waypoints, s)


def resample(points: np.ndarray, spacing: float) -> np.ndarray:
    """``(m, 2)``: each segment of the polyline ``points`` split into equal parts ≤ ``spacing``."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = [p[:1]]
    for a, b in itertools.pairwise(p):
        n = max(1, math.ceil(math.hypot(*(b - a)) / spacing - 1e-9))
        f = np.arange(1, n + 1, dtype=np.float64)[:, None] / n
        out.append(a + f * (b - a))
    return np.concatenate(out)


def split_at_turns(points: np.ndarray, max_turn: float = 0.5) -> list[np.ndarray]:
    """The polyline ``points`` ``(m, 2)`` cut at every corner that turns more than ``max_turn`` radians.

    :class:`~drivers.sim.base.SimBase` drives through intermediate waypoints at full speed and
    overshoots a sharp corner; driving each piece as a goal of its own makes it stop at the
    corner and turn in place. Each piece starts where the previous one ends.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    d = np.diff(p, axis=0)
    moving = np.flatnonzero(np.hypot(d[:, 0], d[:, 1]) > 1e-9)
    cuts = [0]
    if moving.size > 1:
        ang = np.arctan2(d[moving, 1], d[moving, 0])
        turn = np.abs(np.angle(np.exp(1j * np.diff(ang))))
        cuts += [int(moving[k + 1]) for k in np.flatnonzero(turn > max_turn)]
    cuts.append(len(p) - 1)
    return [p[a : b + 1] for a, b in itertools.pairwise(cuts) if b > a] or [p[-1:]]


@dataclass(eq=False)
class RoutePlanner:
    """Plans routes on a grid (see the module docstring).

    Args:
        grid: the map; only free cells are driven on.
        doors: doors to cross along their normals (those of a generated building).
        spaces: ``(rows, cols)`` space ids of the grid's cells (door openings carry door ids
            ``>= DOOR_ID_BASE``), as :class:`~sim.buildings.Building` has them;
            needed for door crossings and tours.
        params: see :class:`RouteParams`.
    """

    grid: OccupancyGrid
    doors: Sequence[Door] = ()
    spaces: np.ndarray | None = None
    params: RouteParams = field(default_factory=RouteParams)

    def __post_init__(self) -> None:
        g, prm = self.grid, self.params
        if self.spaces is not None and self.spaces.shape != g.shape:
            raise ValueError(f"spaces {self.spaces.shape} must have the grid's shape {g.shape}")
        self._doors = {d.id: d for d in self.doors}
        edt = ndimage.distance_transform_edt(np.pad(g.free, 1))[1:-1, 1:-1]
        self._clear = np.maximum(edt - 0.5, 0.0) * g.resolution  # metres to the nearest blocked face
        k = max(1, round(prm.step / g.resolution))
        rows, cols = g.shape
        rr, cc = np.mgrid[k // 2 : rows : k, k // 2 : cols : k]
        clear = self._clear[rr, cc]
        ok = clear >= prm.clearance
        if not ok.any():
            raise MapError(
                f"{g.name}: no free space keeps {prm.clearance} m from the walls; lower RouteParams.clearance"
            )
        index = -np.ones(ok.shape, dtype=np.int64)
        index[ok] = np.arange(int(ok.sum()))
        cost = 1.0 + _CENTRE_WEIGHT * np.maximum(0.0, prm.prefer - clear) ** 2
        src, dst, w = [], [], []
        R, C = ok.shape
        step_m = k * g.resolution
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            c0, c1 = max(0, -dc), C - max(0, dc)
            a, b = index[: R - dr, c0:c1], index[dr:, c0 + dc : c1 + dc]
            m = (a >= 0) & (b >= 0)
            edge_cost = 0.5 * (cost[: R - dr, c0:c1][m] + cost[dr:, c0 + dc : c1 + dc][m])
            src.append(a[m])
            dst.append(b[m])
            w.append(edge_cost * math.hypot(dr, dc) * step_m)
        n = int(ok.sum())
        s, d, ww = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
        self._graph = csr_matrix(
            (np.concatenate((ww, ww)), (np.concatenate((s, d)), np.concatenate((d, s)))), shape=(n, n)
        )
        self._cells = np.column_stack((rr[ok], cc[ok]))
        self._xy = g.cell_to_world(self._cells)
        self._node_clear = clear[ok]

    @classmethod
    def for_building(cls, building: Building, params: RouteParams | None = None) -> RoutePlanner:
        """A planner that knows the building's doors and spaces."""
        return cls(building.grid, building.doors, building.spaces, params or RouteParams())

    # ------------------------------------------------------------------ geometry
    def clearance(self, xy: np.ndarray | Sequence[float]) -> np.ndarray:
        """Metres from world points ``(..., 2)`` to the nearest non-free cell (0 outside the grid)."""
        rc = self.grid.world_to_cell(np.asarray(xy, dtype=np.float64))
        rows, cols = self.grid.shape
        inside = self.grid.in_bounds(rc)
        v = self._clear[np.clip(rc[..., 0], 0, rows - 1), np.clip(rc[..., 1], 0, cols - 1)]
        return np.where(inside, v, 0.0)

    def segment_clearance(self, a: XY, b: XY) -> float:
        """The least clearance (metres) along the straight segment ``a → b``."""
        pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        n = max(2, math.ceil(math.hypot(*(pb - pa)) / (0.5 * self.grid.resolution)) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return float(self.clearance(pa + t * (pb - pa)).min())

    def nearest_clear(self, xy: Sequence[float]) -> Point:
        """The lattice point nearest to world ``xy``: a point ``params.clearance`` metres from
        every obstacle (where a goal too near a wall or furniture is moved to)."""
        p = np.asarray(xy, dtype=np.float64)
        j = int(np.argmin(np.hypot(*(self._xy - p).T)))
        return (float(self._xy[j, 0]), float(self._xy[j, 1]))

    def space_at(self, xy: Sequence[float]) -> int:
        """The space id at a world point (0: a wall, outside, or no ``spaces`` given)."""
        if self.spaces is None:
            return 0
        rc = self.grid.world_to_cell(np.asarray(xy, dtype=np.float64))
        if not bool(self.grid.in_bounds(rc)):
            return 0
        return int(self.spaces[rc[0], rc[1]])

    def anchor(self, space_id: int) -> Point:
        """The lattice point of a space farthest from obstacles (its middle, for a tour)."""
        if self.spaces is None:
            raise ValueError("anchor() needs the grid's spaces (use RoutePlanner.for_building)")
        sp = self.spaces[self._cells[:, 0], self._cells[:, 1]]
        idx = np.flatnonzero(sp == space_id)
        if idx.size == 0:
            raise MapError(f"space {space_id} has no point {self.params.clearance} m away from its walls")
        j = int(idx[np.argmax(self._node_clear[idx])])
        return (float(self._xy[j, 0]), float(self._xy[j, 1]))

    # ------------------------------------------------------------------ planning
    def plan(self, start: XY, goal: XY) -> Route:
        """The route from ``start`` to ``goal`` (world ``(x, y)``).

        Raises:
            MapError: a point is not in reach of the lattice, or no path joins them.
        """
        return self.plan_through([start, goal])

    def plan_through(self, points: Sequence[XY] | np.ndarray) -> Route:
        """One route visiting ``points`` in order (each leg planned as by :meth:`plan`)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if pts.shape[0] < 2 or not np.isfinite(pts).all():
            raise ValueError("plan_through needs at least two finite (x, y) points")
        nodes = [self._attach(p) for p in pts]
        legs: list[np.ndarray] = []
        for i in range(len(pts) - 1):
            _, pred = dijkstra(self._graph, indices=nodes[i], return_predecessors=True)
            legs.append(self._lattice_path(pred, nodes[i], nodes[i + 1], pts[i], pts[i + 1]))
        return self._route(legs)

    def tour(
        self,
        start: Sequence[float],
        spaces: Sequence[int] | None = None,
        *,
        max_spaces: int | None = None,
        closed: bool = True,
    ) -> Route:
        """A route from ``start`` through the middle of each space, nearest unvisited first.

        Args:
            start: world ``(x, y)``.
            spaces: ids to visit; None: every space id in the grid's ``spaces`` (door
                openings excepted); :func:`building_tour` passes a building's rooms and halls.
            max_spaces: visit at most this many (the nearest ones first).
            closed: come back to ``start`` at the end (a loop).
        """
        if self.spaces is None:
            raise ValueError("tour() needs the grid's spaces (use RoutePlanner.for_building)")
        if spaces is None:
            ids = np.unique(self.spaces)
            spaces = [int(i) for i in ids if 0 < i < DOOR_ID_BASE]
        p0 = np.asarray(start, dtype=np.float64)
        here = self._attach(p0)
        targets: list[tuple[int, int, Point]] = []
        for sid in spaces:
            try:
                xy = self.anchor(sid)
            except MapError:
                continue
            targets.append((sid, self._nearest_node(np.asarray(xy)), xy))
        sources = [here] + [t[1] for t in targets]
        dist, pred = dijkstra(self._graph, indices=sources, return_predecessors=True)
        order: list[int] = []
        cur = 0
        left = set(range(len(targets)))
        limit = len(targets) if max_spaces is None else max(0, int(max_spaces))
        while left and len(order) < limit:
            reach = [j for j in left if np.isfinite(dist[cur, targets[j][1]])]
            if not reach:
                break
            nxt = min(reach, key=lambda j: dist[cur, targets[j][1]])
            order.append(nxt)
            left.discard(nxt)
            cur = nxt + 1
        stops = [(sources[0], p0)] + [(targets[j][1], np.asarray(targets[j][2])) for j in order]
        if closed and order:
            stops.append((sources[0], p0))
        row = {node: r for r, node in enumerate(sources)}
        legs = [
            self._lattice_path(pred[row[a]], a, b, pa, pb) for (a, pa), (b, pb) in itertools.pairwise(stops)
        ]
        if not legs:
            return Route(p0[None, :], spacing=self.params.spacing)
        route = self._route(legs)
        return Route(
            route.waypoints, tuple(targets[j][0] for j in order), route.doors, spacing=self.params.spacing
        )

    # ------------------------------------------------------------------ internals
    def _nearest_node(self, xy: np.ndarray) -> int:
        return int(np.argmin(np.hypot(*(self._xy - xy).T)))

    def _attach(self, p: np.ndarray) -> int:
        """The lattice node a point connects to by a clear straight segment (nearest first)."""
        d = np.hypot(*(self._xy - p).T)
        near = np.argsort(d)[:16]
        need = min(self.params.clearance, float(self.clearance(p))) - self.grid.resolution
        for j in near:
            if d[j] > 4 * self.params.step + 1.0:
                break
            if self.segment_clearance(p, self._xy[j]) >= max(need, 0.0):
                return int(j)
        raise MapError(
            f"({p[0]:.2f}, {p[1]:.2f}) is not in reach of the free space that keeps "
            f"{self.params.clearance} m from the walls; choose a point in the open"
        )

    def _lattice_path(self, pred: np.ndarray, a: int, b: int, pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
        """``(k, 2)``: ``pa``, the lattice nodes from ``a`` to ``b``, ``pb``."""
        seq = [b]
        while seq[-1] != a:
            p = int(pred[seq[-1]])
            if p < 0:
                raise MapError(
                    f"no route from ({pa[0]:.2f}, {pa[1]:.2f}) to ({pb[0]:.2f}, {pb[1]:.2f}) keeps "
                    f"{self.params.clearance} m from the walls"
                )
            seq.append(p)
        return np.vstack([pa, self._xy[seq[::-1]], pb])

    def _route(self, legs: list[np.ndarray]) -> Route:
        raw = np.vstack([legs[0]] + [leg[1:] for leg in legs[1:]])
        keep = np.ones(len(raw), dtype=bool)
        keep[1:] = np.hypot(*np.diff(raw, axis=0).T) > 1e-9
        raw = raw[keep]
        # the points each leg starts and ends at are fixed waypoints
        fixed_pts = {tuple(leg[0]) for leg in legs} | {tuple(leg[-1]) for leg in legs}
        pts, anchors, doors = self._door_crossings(raw, fixed_pts)
        corners = [pts[0]]
        for i0, i1 in itertools.pairwise(anchors):
            corners.extend(self._straighten(pts[i0 : i1 + 1])[1:])
        corners = self._no_turning_back(corners)
        corners = self._no_turning_back(corners[::-1])[::-1]
        return Route(np.asarray(corners), doors=tuple(doors), spacing=self.params.spacing)

    def _no_turning_back(self, corners: list[np.ndarray]) -> list[np.ndarray]:
        """Drop the first waypoints the route would turn back from: a start already in a
        doorway, past the point the crossing approaches it from, went back to that point
        first (and a robot re-planning every few tenths of a second, as a follower does, turned
        round in the door for ever). A waypoint goes when the route turns back after it (by
        more than 120°) and the start sees the next one in the clear."""
        pts = list(corners)
        while len(pts) >= 3:
            a, b, c = (np.asarray(q, dtype=np.float64) for q in pts[:3])
            need = min(self.params.clearance, float(self.clearance(a))) - self.grid.resolution
            u, v = b - a, c - b
            back = float(u @ v) < -0.5 * float(np.hypot(*u) * np.hypot(*v))  # turns by over 120°
            if back and self.segment_clearance(a, c) >= max(need, 0.0):
                del pts[1]
            else:
                break
        return pts

    def _door_crossings(
        self, raw: np.ndarray, fixed_pts: set[tuple[float, float]]
    ) -> tuple[np.ndarray, list[int], list[int]]:
        """Replace each door crossing of the lattice path by approach-centre-approach waypoints.

        Returns the new points, the indices of the fixed ones (sorted, first and last
        included) and the ids of the doors crossed, in order.
        """
        n = len(raw)
        is_fixed = np.array([i in (0, n - 1) or tuple(p) in fixed_pts for i, p in enumerate(raw)])
        crossings: list[tuple[int, list[np.ndarray], int, int]] = []  # (i0, points, i1, door id)
        if self.spaces is not None and self._doors:
            cells = self.grid.world_to_cell(raw)
            rows, cols = self.grid.shape
            ids = np.where(
                self.grid.in_bounds(cells),
                self.spaces[np.clip(cells[:, 0], 0, rows - 1), np.clip(cells[:, 1], 0, cols - 1)],
                0,
            )
            i = 1
            while i < n - 1:
                did = int(ids[i])
                if did < DOOR_ID_BASE or did not in self._doors:
                    i += 1
                    continue
                j = i
                while j + 1 < n and int(ids[j + 1]) == did:
                    j += 1
                found = self._crossing(self._doors[did], raw, i, j)
                if (
                    found is not None
                    and not is_fixed[found[0] + 1 : found[2]].any()
                    and (not crossings or found[0] >= crossings[-1][2])
                ):
                    crossings.append((*found, did))
                i = j + 1
        out: list[np.ndarray] = []
        fixed: list[int] = []
        doors: list[int] = []
        k = 0
        for i0, pts3, i1, did in crossings:
            for i in range(k, i0 + 1):
                if is_fixed[i]:
                    fixed.append(len(out))
                out.append(raw[i])
            for p in pts3:
                fixed.append(len(out))
                out.append(p)
            doors.append(did)
            k = i1
        for i in range(k, n):
            if is_fixed[i]:
                fixed.append(len(out))
            out.append(raw[i])
        return np.asarray(out), sorted(set(fixed)), doors

    def _crossing(
        self, door: Door, raw: np.ndarray, i: int, j: int
    ) -> tuple[int, list[np.ndarray], int] | None:
        """Waypoints crossing ``door`` along its normal, replacing ``raw[i0+1 : i1]``."""
        c = np.asarray(door.center, dtype=np.float64)
        nrm = np.array([math.cos(door.orientation), math.sin(door.orientation)])
        if i == 0 or j >= len(raw) - 1:
            return None
        sign = 1.0 if float(np.dot(raw[j + 1] - raw[i - 1], nrm)) >= 0 else -1.0
        half_width = 0.5 * door.width
        tol = self.grid.resolution
        for approach in (self.params.door_approach, 0.5 * self.params.door_approach, 0.0):
            reach = 0.5 * door.wall_thickness + approach
            a_in, a_out = c - sign * reach * nrm, c + sign * reach * nrm
            i0 = i - 1
            while i0 > 0 and np.hypot(*(raw[i0] - c)) < reach:
                i0 -= 1
            i1 = j + 1
            while i1 < len(raw) - 1 and np.hypot(*(raw[i1] - c)) < reach:
                i1 += 1
            need = min(self.params.prefer, half_width, float(self.clearance(raw[i0 : i1 + 1]).min())) - tol
            legs = ((raw[i0], a_in), (a_in, c), (c, a_out), (a_out, raw[i1]))
            if all(self.segment_clearance(p, q) >= need for p, q in legs):
                return i0, [a_in, c, a_out], i1
        return None

    def _straighten(self, pts: np.ndarray) -> list[np.ndarray]:
        """String pulling between two fixed ends, keeping the clearance the path had."""
        clear = np.minimum(self.clearance(pts), self.params.prefer)
        tol = self.grid.resolution
        out = [pts[0]]
        i, n = 0, len(pts)
        while i < n - 1:
            best = i + 1
            lowest = min(clear[i], clear[i + 1])
            for j in range(i + 2, n):
                lowest = min(lowest, clear[j])
                if self.segment_clearance(pts[i], pts[j]) >= lowest - tol:
                    best = j
                else:
                    break
            out.append(pts[best])
            i = best
        return out


def building_tour(
    building: Building,
    start: Sequence[float] | None = None,
    *,
    max_rooms: int | None = None,
    closed: bool = True,
    params: RouteParams | None = None,
    planner: RoutePlanner | None = None,
) -> Route:
    """A tour of a generated building's rooms and halls from ``start`` (default: :func:`corridor_start`)."""
    planner = planner or RoutePlanner.for_building(building, params)
    p0 = corridor_start(building, planner)[:2] if start is None else tuple(start)
    return planner.tour(p0, [r.id for r in building.rooms], max_spaces=max_rooms, closed=closed)


def corridor_start(building: Building, planner: RoutePlanner | None = None) -> tuple[float, float, float]:
    """A start pose on the axis of the building's first corridor, heading along it.

    The centre of the corridor's longest straight piece when the lattice reaches it, else
    the corridor's most open point.
    """
    planner = planner or RoutePlanner.for_building(building)
    corridor = building.corridors[0] if building.corridors else building.rooms[0]
    x0, y0, x1, y1 = max(corridor.rects, key=lambda r: max(r[2] - r[0], r[3] - r[1]))
    heading = 0.0 if (x1 - x0) >= (y1 - y0) else math.pi / 2
    centre = ((x0 + x1) / 2, (y0 + y1) / 2)
    if float(planner.clearance(centre)) >= planner.params.clearance:
        return (centre[0], centre[1], heading)
    x, y = planner.anchor(corridor.id)
    return (x, y, heading)
