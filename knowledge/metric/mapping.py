"""An occupancy grid from laser scans taken at known poses ("mapping with known poses").

:class:`ScanMapper` counts, per cell, how often a beam ended there (a *hit*) and how often
a beam crossed it (a *miss*), as GMapping's counting model does; a cell's occupancy is
``hits / (hits + misses)``. Beams that hit nothing (``range >= range_max``) and invalid ones
(below ``range_min``, NaN) count nothing — an open window or a dark surface says nothing
certain about the cells along it. Beams longer than ``max_range`` are not used (far returns
are sparse and their angle error grows with range). The grid grows as the scans reach new
ground.

:meth:`ScanMapper.grid` gives the :class:`~knowledge.metric.grid.OccupancyGrid`: occupied
where the occupancy is at least ``occupied``, free where a beam crossed the cell and the
occupancy is lower, unknown where no beam reached; in the frame of the poses. For pictures,
and for a map built from a log with SLAM-corrected poses (the localization issue's ground
truth map).

With ``changes=True`` the mapper also lists the cells whose state (unknown, free, occupied)
an integrated scan changed (:meth:`ScanMapper.take_changes`), in *lattice* indices that stay
put when the grid grows: what a pose tracker needs to keep a likelihood field of the whole
map up to date without remaking it (:class:`~knowledge.localization.tracking_field.TrackingField`).

Poses are the laser's ``(x, y, theta)`` in metres and radians; beam ``i`` points at
``angles[i]`` radians from the laser's heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from knowledge.metric.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

__all__ = ["CELL_FREE", "CELL_OCCUPIED", "CELL_UNKNOWN", "MappingParams", "ScanMapper"]


@dataclass(frozen=True)
class MappingParams:
    """How :class:`ScanMapper` builds its grid.

    Attributes:
        resolution: cell side, metres.
        max_range: metres; longer beams are not used.
        occupied: the occupancy (hits over hits and misses) from which a cell is occupied.
        margin: metres of unknown border kept around what was seen (and the step the grid
            grows by).
    """

    resolution: float = 0.05
    max_range: float = 20.0
    occupied: float = 0.25
    margin: float = 2.0

    def __post_init__(self) -> None:
        for name in ("resolution", "max_range", "margin"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"MappingParams.{name} must be a positive number, got {v!r}")
        if not (0.0 < self.occupied <= 1.0):
            raise ValueError(f"MappingParams.occupied must be in (0, 1], got {self.occupied!r}")


#: metres of room kept around the grid in memory, each side (at least half the grid's size)
_ROOM = 40.0

#: ``out`` of :func:`_integrate` when the changes are not listed
_NO_CHANGES = np.empty((0, 3), dtype=np.int64)

#: cell states in :meth:`ScanMapper.take_changes`
CELL_UNKNOWN, CELL_FREE, CELL_OCCUPIED = 0, 1, 2


@numba.njit(cache=True, nogil=True)
def _state(h: int, m: int, occupied: float) -> int:
    if h + m == 0:
        return 0
    if h > 0 and h >= occupied * (h + m):
        return 2
    return 1


@numba.njit(cache=True, nogil=True)
def _integrate(
    hits: np.ndarray,
    misses: np.ndarray,
    x0: float,
    y0: float,
    ex: np.ndarray,
    ey: np.ndarray,
    res: float,
    ox: float,
    oy: float,
    occupied: float,
    out: np.ndarray,
    track: bool,
) -> int:
    """Trace each beam from ``(x0, y0)`` to ``(ex[i], ey[i])`` (world metres) through the grid
    whose cell (0, 0) has its lower-left corner at ``(ox, oy)``; row = y index (bottom up).
    The cells before the end cell get a miss, the end cell a hit. With ``track``, every count
    that changes a cell's state (unknown 0, free 1, occupied 2: :meth:`ScanMapper.window`'s
    rule) appends ``(row, col, new state)`` to ``out``, in order (``out`` must have room for
    one per cell visited); returns how many rows it wrote."""
    rows, cols = hits.shape
    n = 0
    c0 = math.floor((x0 - ox) / res)
    r0 = math.floor((y0 - oy) / res)
    for i in range(ex.shape[0]):
        c1 = math.floor((ex[i] - ox) / res)
        r1 = math.floor((ey[i] - oy) / res)
        dc = abs(c1 - c0)
        dr = abs(r1 - r0)
        sc = 1 if c1 > c0 else -1
        sr = 1 if r1 > r0 else -1
        err = dc - dr
        c, r = c0, r0
        while c != c1 or r != r1:  # Bresenham's walk
            if 0 <= r < rows and 0 <= c < cols:
                h, m = hits[r, c], misses[r, c]
                misses[r, c] = m + 1
                if track:
                    before, after = _state(h, m, occupied), _state(h, m + 1, occupied)
                    if after != before:
                        out[n, 0], out[n, 1], out[n, 2] = r, c, after
                        n += 1
            e2 = 2 * err
            if e2 > -dr:
                err -= dr
                c += sc
            if e2 < dc:
                err += dc
                r += sr
        if 0 <= r1 < rows and 0 <= c1 < cols:
            h, m = hits[r1, c1], misses[r1, c1]
            hits[r1, c1] = h + 1
            if track:
                before, after = _state(h, m, occupied), _state(h + 1, m, occupied)
                if after != before:
                    out[n, 0], out[n, 1], out[n, 2] = r1, c1, after
                    n += 1
    return n


class ScanMapper:
    """Integrates scans at known poses into a growing grid of counts (see the module docstring).

    Args:
        params: the parameters.
        changes: list the cells each scan changes (:meth:`take_changes`).
    """

    def __init__(self, params: MappingParams | None = None, *, changes: bool = False) -> None:
        self.params = params or MappingParams()
        self._hits = np.zeros((0, 0), dtype=np.int32)
        self._misses = np.zeros((0, 0), dtype=np.int32)
        # the memory the counts are views of, and where the grid's cell (0, 0) is in it
        self._room: tuple[np.ndarray, np.ndarray] | None = None
        self._room_at = (0, 0)
        self._origin = (0.0, 0.0)  # world (x, y) of cell (row 0, col 0)'s lower-left corner
        # the lattice: cell (row, col) of the grid is lattice cell (row - r, col - c) for
        # (r, c) = _anchor; lattice cell (0, 0) is the first grid's cell (0, 0)
        self._anchor = (0, 0)
        self._lattice_origin: tuple[float, float] | None = None
        self._track_changes = bool(changes)
        self._changes: list[np.ndarray] = []
        self.scans = 0

    def _cover(self, xmin: float, ymin: float, xmax: float, ymax: float) -> None:
        """Grow the grid (by at least a margin) so that it covers the box."""
        prm = self.params
        res = prm.resolution
        rows, cols = self._hits.shape
        ox, oy = self._origin
        if rows and ox <= xmin and oy <= ymin and xmax < ox + cols * res and ymax < oy + rows * res:
            return
        if not rows:
            new_ox, new_oy = xmin - prm.margin, ymin - prm.margin
            shift_c = shift_r = 0
            x1, y1 = xmax + prm.margin, ymax + prm.margin
            self._lattice_origin = (new_ox, new_oy)
        else:
            # the new origin lies a whole number of cells from the old one: the lattice stays
            shift_c = max(0, math.ceil((ox - (xmin - prm.margin)) / res)) if xmin < ox else 0
            shift_r = max(0, math.ceil((oy - (ymin - prm.margin)) / res)) if ymin < oy else 0
            new_ox, new_oy = ox - shift_c * res, oy - shift_r * res
            x1 = max(ox + cols * res, xmax + prm.margin if xmax >= ox + cols * res else 0.0)
            y1 = max(oy + rows * res, ymax + prm.margin if ymax >= oy + rows * res else 0.0)
        new_cols = math.ceil((x1 - new_ox) / res)
        new_rows = math.ceil((y1 - new_oy) / res)
        # the counts live in larger zeroed memory, with room on each side: the grid grows in
        # place (the new cells are zero, their pages untouched until used); only a grid that
        # outgrows its room is copied, into room at least half its size each side
        br, bc = self._room_at[0] - shift_r, self._room_at[1] - shift_c
        room = self._room
        if (
            room is None
            or br < 0
            or bc < 0
            or br + new_rows > room[0].shape[0]
            or bc + new_cols > room[0].shape[1]
        ):
            pr = max(math.ceil(_ROOM / res), new_rows // 2)
            pc = max(math.ceil(_ROOM / res), new_cols // 2)
            shape = (new_rows + 2 * pr, new_cols + 2 * pc)
            room = (np.zeros(shape, dtype=np.int32), np.zeros(shape, dtype=np.int32))
            if rows:
                room[0][pr + shift_r : pr + shift_r + rows, pc + shift_c : pc + shift_c + cols] = self._hits
                room[1][pr + shift_r : pr + shift_r + rows, pc + shift_c : pc + shift_c + cols] = self._misses
            self._room, br, bc = room, pr, pc
        self._room_at = (br, bc)
        self._hits = room[0][br : br + new_rows, bc : bc + new_cols]
        self._misses = room[1][br : br + new_rows, bc : bc + new_cols]
        self._origin = (new_ox, new_oy)
        self._anchor = (self._anchor[0] + shift_r, self._anchor[1] + shift_c)

    def add(
        self,
        ranges: np.ndarray,
        angles: np.ndarray,
        pose: tuple[float, float, float] | np.ndarray,
        *,
        range_max: float,
        range_min: float = 0.0,
    ) -> None:
        """Integrate one scan: ``(n,)`` ranges (metres) at ``(n,)`` angles (radians) seen from
        the laser's ``pose`` (x, y, theta)."""
        r = np.asarray(ranges, dtype=np.float64)
        a = np.asarray(angles, dtype=np.float64)
        if r.ndim != 1 or a.shape != r.shape:
            raise ValueError(f"ranges and angles must be 1-D of the same length, got {r.shape} and {a.shape}")
        x, y, th = (float(v) for v in pose)
        if not all(math.isfinite(v) for v in (x, y, th)):
            raise ValueError(f"pose must be finite (x, y, theta), got {pose!r}")
        prm = self.params
        with np.errstate(invalid="ignore"):
            use = np.isfinite(r) & (r > 0.0) & (r >= range_min) & (r < range_max * (1.0 - 1e-6))
            use &= r <= prm.max_range
        r, a = r[use], a[use]
        self.scans += 1
        if r.size == 0:
            return
        ex = x + r * np.cos(th + a)
        ey = y + r * np.sin(th + a)
        self._cover(
            min(x, float(ex.min())), min(y, float(ey.min())), max(x, float(ex.max())), max(y, float(ey.max()))
        )
        ox, oy = self._origin
        res = self.params.resolution
        if not self._track_changes:
            _integrate(self._hits, self._misses, x, y, ex, ey, res, ox, oy, prm.occupied, _NO_CHANGES, False)
            return
        # room for one change per cell visited: a beam visits at most |dc| + |dr| + 1 cells,
        # |dc| <= |Δx| / res + 1 (likewise |dr|)
        cap = int(np.sum(np.abs(ex - x) + np.abs(ey - y)) / res) + 3 * int(ex.size) + 1
        out = np.empty((cap, 3), dtype=np.int64)
        n = _integrate(self._hits, self._misses, x, y, ex, ey, res, ox, oy, prm.occupied, out, True)
        if n:
            ch = out[:n].copy()
            ch[:, 0] -= self._anchor[0]
            ch[:, 1] -= self._anchor[1]
            self._changes.append(ch)

    @property
    def lattice_origin(self) -> tuple[float, float] | None:
        """World ``(x, y)`` of the lower-left corner of lattice cell ``(0, 0)`` (None before
        the first beam): lattice cell ``(row, col)`` spans ``x`` from ``x0 + col·resolution``,
        ``y`` from ``y0 + row·resolution``, however the grid grew."""
        return self._lattice_origin

    def take_changes(self) -> np.ndarray:
        """``(K, 3)`` int64 ``(lattice row, lattice col, state)`` of every change of a cell's
        state (:data:`CELL_UNKNOWN`, :data:`CELL_FREE`, :data:`CELL_OCCUPIED`, as
        :meth:`window` tells them) since the last call, in the order they happened (a cell
        may appear more than once: its last row holds its state now). Needs ``changes=True``."""
        if not self._track_changes:
            raise ValueError("this ScanMapper does not list its changes: make it with changes=True")
        if not self._changes:
            return np.zeros((0, 3), dtype=np.int64)
        out = np.concatenate(self._changes) if len(self._changes) > 1 else self._changes[0]
        self._changes = []
        return out

    def copy(self) -> ScanMapper:
        """An independent copy of the counts so far (to build a grid elsewhere)."""
        other = ScanMapper(self.params)
        other._hits, other._misses, other._origin = self._hits.copy(), self._misses.copy(), self._origin
        other._anchor, other._lattice_origin = self._anchor, self._lattice_origin
        other.scans = self.scans
        return other

    def window(
        self, xmin: float, ymin: float, xmax: float, ymax: float
    ) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
        """The occupied and free cells of a box of the map, for scan matching against it.

        Returns:
            ``(rows, cols)`` bool occupied and free masks in *map orientation* (row 0 at the
            bottom: row = y index), and the world ``(x, y)`` of the lower-left corner of cell
            ``(0, 0)``. The box is snapped to the grid's cells; parts outside the grid are
            unknown (neither occupied nor free).
        """
        res = self.params.resolution
        ox, oy = self._origin
        c0, r0 = math.floor((xmin - ox) / res), math.floor((ymin - oy) / res)
        c1, r1 = math.ceil((xmax - ox) / res), math.ceil((ymax - oy) / res)
        rows, cols = max(r1 - r0, 1), max(c1 - c0, 1)
        hits = np.zeros((rows, cols), dtype=np.int32)
        misses = np.zeros((rows, cols), dtype=np.int32)
        R, C = self._hits.shape
        a0, a1, b0, b1 = max(r0, 0), min(r1, R), max(c0, 0), min(c1, C)
        if a0 < a1 and b0 < b1:
            hits[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0] = self._hits[a0:a1, b0:b1]
            misses[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0] = self._misses[a0:a1, b0:b1]
        seen = hits + misses
        occupied = (hits > 0) & (hits >= self.params.occupied * seen)
        return occupied, (seen > 0) & ~occupied, (ox + c0 * res, oy + r0 * res)

    def grid(self, name: str = "scans") -> OccupancyGrid:
        """The map so far (image orientation, origin at its lower-left corner)."""
        hits, misses = self._hits, self._misses
        if hits.size == 0:
            hits = misses = np.zeros((1, 1), dtype=np.int32)
        seen = hits + misses
        state = np.full(hits.shape, UNKNOWN, dtype=np.int8)
        state[seen > 0] = FREE
        state[(hits > 0) & (hits >= self.params.occupied * seen)] = OCCUPIED
        ox, oy = self._origin
        return OccupancyGrid(state[::-1].copy(), self.params.resolution, (ox, oy, 0.0), name)
