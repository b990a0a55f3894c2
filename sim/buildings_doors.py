"""Doors of generated buildings: where a room's wall faces another space, and cutting openings.

Works on the raster of space ids (``(rows, cols)`` int32, 0 = wall) before any door is cut.
For each side of a room, :func:`side_runs` finds the stretches of wall of constant thickness
with one and the same space right behind them; a door is an opening cut through such a
stretch. Each room first gets a door to a corridor or hall it faces; rooms that face none
are then connected to an already connected neighbour room by an inner door, and a few more
inner doors are added at random. Rooms that still cannot be reached are reported as sealed.

Doorway labels follow the IPA labelled maps: a rectangle across the opening, a little wider
than the opening (0–0.1 m each side along the wall) and reaching 0.15–0.55 m into the room
and 0.1–0.5 m into the other space, so 0.6–1.3 m deep in all with the wall.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.buildings_layout import Dims, Rect

#: Door widths (metres).
DOOR_MIN_WIDTH = 0.8
DOOR_MAX_WIDTH = 1.2
#: Thickest wall a door is cut through (metres).
MAX_WALL = 0.4
#: Door ids (in ``Building.spaces`` and ``Door.id``) start here, above every space id.
DOOR_ID_BASE = 10_000


@dataclass(frozen=True)
class Run:
    """A stretch of a room's ``side`` (positions ``start``–``stop`` along it, cells) where
    ``target`` lies behind a wall ``gap`` cells thick."""

    side: str
    start: int
    stop: int
    gap: int
    target: int

    @property
    def length(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class DoorCut:
    """A door in cells: the opening through the wall and the doorway label rectangle."""

    id: int
    room: int
    target: int
    side: str
    opening: Rect
    label: Rect
    keepout: Rect

    @property
    def width(self) -> int:
        """Opening width along the wall (cells)."""
        return self.opening.w if self.side in ("top", "bottom") else self.opening.h

    @property
    def gap(self) -> int:
        """Wall thickness (cells)."""
        return self.opening.h if self.side in ("top", "bottom") else self.opening.w


def side_runs(spaces: np.ndarray, r: Rect, side: str, max_gap: int) -> list[Run]:
    """Stretches of ``r``'s ``side`` behind which one space lies at a constant wall thickness.

    ``spaces`` must have at least ``max_gap`` cells of margin around ``r``.
    """
    if side == "top":
        band = spaces[r.y0 - max_gap : r.y0, r.x0 : r.x1][::-1]
        off = r.x0
    elif side == "bottom":
        band = spaces[r.y1 : r.y1 + max_gap, r.x0 : r.x1]
        off = r.x0
    elif side == "left":
        band = spaces[r.y0 : r.y1, r.x0 - max_gap : r.x0][:, ::-1].T
        off = r.y0
    else:
        band = spaces[r.y0 : r.y1, r.x1 : r.x1 + max_gap].T
        off = r.y0
    nz = band != 0
    gap = nz.argmax(axis=0)
    target = np.where(nz.any(axis=0), band[gap, np.arange(band.shape[1])], 0)
    key = target.astype(np.int64) * (max_gap + 1) + gap
    runs: list[Run] = []
    bounds = np.flatnonzero(np.diff(key)) + 1
    starts = np.concatenate([[0], bounds])
    stops = np.concatenate([bounds, [key.size]])
    for s, e in zip(starts, stops, strict=True):
        if target[s] != 0 and gap[s] >= 1:
            runs.append(Run(side, int(s + off), int(e + off), int(gap[s]), int(target[s])))
    return runs


def _opening(r: Rect, run: Run, start: int, width: int) -> Rect:
    g = run.gap
    if run.side == "top":
        return Rect(start, r.y0 - g, start + width, r.y0)
    if run.side == "bottom":
        return Rect(start, r.y1, start + width, r.y1 + g)
    if run.side == "left":
        return Rect(r.x0 - g, start, r.x0, start + width)
    return Rect(r.x1, start, r.x1 + g, start + width)


def _grow(o: Rect, side: str, along: int, into_room: int, into_other: int) -> Rect:
    """``o`` widened by ``along`` on both ends and deepened towards the room and the other side."""
    if side == "top":
        return Rect(o.x0 - along, o.y0 - into_other, o.x1 + along, o.y1 + into_room)
    if side == "bottom":
        return Rect(o.x0 - along, o.y0 - into_room, o.x1 + along, o.y1 + into_other)
    if side == "left":
        return Rect(o.x0 - into_other, o.y0 - along, o.x1 + into_room, o.y1 + along)
    return Rect(o.x0 - into_room, o.y0 - along, o.x1 + into_other, o.y1 + along)


class DoorPlacer:
    """Places the doors of one building (see the module docstring)."""

    def __init__(
        self,
        rng: np.random.Generator,
        spaces: np.ndarray,
        rooms: dict[int, Rect],
        open_ids: set[int],
        dims: Dims,
        door_width: float,
    ) -> None:
        self.rng = rng
        self.rooms = rooms
        self.open_ids = open_ids
        self.d = dims
        self.door_width = door_width
        self.margin = dims.cells(0.1)
        self.clear = dims.cells(0.4)
        # the doorway label's depth and overhang, drawn once per building like one annotator's habit
        self.label_room = rng.uniform(0.15, 0.55)
        self.label_other = rng.uniform(0.10, 0.50)
        self.label_along = rng.uniform(0.0, 0.10)
        g = dims.cells(MAX_WALL)
        self.runs = {
            rid: [run for s in ("top", "bottom", "left", "right") for run in side_runs(spaces, r, s, g)]
            for rid, r in rooms.items()
        }
        self.doors: list[DoorCut] = []

    def _width(self, rid: int) -> int:
        r = self.rooms[rid]
        w = self.door_width + self.rng.uniform(-0.05, 0.15)
        if r.area * self.d.res**2 >= 30.0:
            w += self.rng.uniform(0.0, 0.15)
        return self.d.cells(float(np.clip(w, DOOR_MIN_WIDTH, DOOR_MAX_WIDTH)))

    def _fits(self, run: Run, width: int) -> bool:
        return run.length >= width + 2 * self.margin

    def _free_spot(self, o: Rect) -> bool:
        c = self.clear
        grown = Rect(o.x0 - c, o.y0 - c, o.x1 + c, o.y1 + c)
        return not any(grown.overlaps(dc.opening) for dc in self.doors)

    def place(self, rid: int, run: Run) -> DoorCut | None:
        """Cut a door from room ``rid`` through ``run``; None if no spot is left on it."""
        width = self._width(rid)
        if not self._fits(run, width):
            width = self.d.cells(DOOR_MIN_WIDTH)
            if not self._fits(run, width):
                return None
        lo, hi = run.start + self.margin, run.stop - self.margin - width
        r = self.rooms[rid]
        for _ in range(6):
            if self.rng.random() < 0.6:
                # most office doors sit near a corner of the room
                off = self.d.cells(self.rng.uniform(0.05, 0.5))
                start = lo + off if self.rng.random() < 0.5 else hi - off
                start = min(max(start, lo), hi)
            else:
                start = int(self.rng.integers(lo, hi + 1))
            o = _opening(r, run, start, width)
            if self._free_spot(o):
                d = self.d
                jit = self.rng.uniform(-0.05, 0.05, size=2)
                label = _grow(
                    o,
                    run.side,
                    round(self.label_along / d.res),
                    d.cells(self.label_room + jit[0]),
                    d.cells(self.label_other + jit[1]),
                )
                keep = _grow(o, run.side, d.cells(0.35), d.cells(1.0), d.cells(1.0))
                dc = DoorCut(DOOR_ID_BASE + len(self.doors) + 1, rid, run.target, run.side, o, label, keep)
                self.doors.append(dc)
                return dc
        return None

    def _pick(self, runs: list[Run]) -> Run | None:
        ok = [r for r in runs if self._fits(r, self.d.cells(DOOR_MIN_WIDTH))]
        if not ok:
            return None
        p = np.array([r.length for r in ok], dtype=float)
        return ok[int(self.rng.choice(len(ok), p=p / p.sum()))]

    def place_all(self, inner_prob: float) -> list[int]:
        """Doors for every room; returns the ids of rooms that could not be connected."""
        connected: set[int] = set()
        for rid in sorted(self.rooms):
            outer = [r for r in self.runs[rid] if r.target in self.open_ids]
            run = self._pick(outer)
            if run is not None and self.place(rid, run) is not None:
                connected.add(rid)
                r = self.rooms[rid]
                if max(r.w, r.h) * self.d.res >= 7.0 and self.rng.random() < 0.4:
                    second = self._pick(outer)
                    if second is not None:
                        self.place(rid, second)
        progress = True
        while progress:
            progress = False
            for rid in sorted(set(self.rooms) - connected):
                inner = [r for r in self.runs[rid] if r.target in connected]
                run = self._pick(inner)
                if run is not None and self.place(rid, run) is not None:
                    connected.add(rid)
                    progress = True
        pairs = {frozenset((dc.room, dc.target)) for dc in self.doors}
        for rid in sorted(connected):
            for run in self.runs[rid]:
                pair = frozenset((rid, run.target))
                if run.target in connected and run.target in self.rooms and pair not in pairs:
                    pairs.add(pair)
                    if self.rng.random() < inner_prob:
                        self.place(rid, run)
        return sorted(set(self.rooms) - connected)
