"""Furniture of generated buildings: what each kind of room holds, placed without blocking doors.

Items are axis-aligned footprints in cells. What the occupancy grid shows of them is what a
laser some 0.3 m above the floor sees: cabinets, shelves, counters, couches, TV stands and the
like are solid; tables and desks only show their four legs; chairs, plants and buckets are
small round blobs. Every item keeps clear of the doors' keep-out zones (the opening, 0.35 m
either side of it and 1 m deep into both spaces), and an item is only accepted if the free
cells of its space stay one 4-connected region, so furniture never seals off any free cell.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from sim.buildings_layout import Dims, Rect

#: How each kind is drawn in the grid: "solid", "legs" or "disk".
SHAPES: dict[str, str] = {
    "table": "legs",
    "desk": "legs",
    "chair": "disk",
    "plant": "disk",
    "bucket": "disk",
    "cabinet": "solid",
    "shelf": "solid",
    "counter": "solid",
    "fridge": "solid",
    "couch": "solid",
    "tv": "solid",
    "equipment": "solid",
    "printer": "solid",
    "pillar": "solid",
    "partition": "solid",
    "charging_station": "solid",
}

#: Yaw (rad) of an item standing against each wall: its front faces into the space.
_WALL_YAW: dict[str, float] = {"top": math.pi, "bottom": 0.0, "left": -math.pi / 2, "right": math.pi / 2}
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=np.uint8)


@dataclass(frozen=True)
class Item:
    """A placed piece of furniture: footprint (cells), yaw (rad), the space it stands in."""

    kind: str
    rect: Rect
    yaw: float
    space: int


class Furnisher:
    """Places items one at a time, checking each against walls, doors, other items and connectivity."""

    def __init__(
        self,
        rng: np.random.Generator,
        spaces: np.ndarray,
        keepout: np.ndarray,
        dims: Dims,
        table_legs: bool,
    ) -> None:
        self.rng = rng
        self.spaces = spaces
        self.keepout = keepout
        self.d = dims
        self.table_legs = table_legs
        self.mask = np.zeros(spaces.shape, dtype=bool)
        self.items: list[Item] = []

    # ------------------------------------------------------------------ geometry
    def cells(self, m: float) -> int:
        return self.d.cells(m)

    def uniform(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def render(self, kind: str, r: Rect, out: np.ndarray, ox: int = 0, oy: int = 0) -> None:
        """Draw an item's footprint into ``out`` (whose cell (0, 0) is raster cell (oy, ox))."""
        shape = SHAPES.get(kind, "solid")
        if shape == "legs" and not self.table_legs:
            shape = "solid"
        x0, y0, x1, y1 = r.x0 - ox, r.y0 - oy, r.x1 - ox, r.y1 - oy
        if shape == "solid":
            out[y0:y1, x0:x1] = True
        elif shape == "legs":
            k = min(self.cells(0.08), r.w // 2, r.h // 2)
            for ys in (slice(y0, y0 + k), slice(y1 - k, y1)):
                for xs in (slice(x0, x0 + k), slice(x1 - k, x1)):
                    out[ys, xs] = True
        else:
            yy, xx = np.mgrid[y0:y1, x0:x1]
            cy, cx = (y0 + y1 - 1) / 2, (x0 + x1 - 1) / 2
            rad = max(r.w, r.h) / 2
            out[y0:y1, x0:x1] |= (yy - cy) ** 2 + (xx - cx) ** 2 <= rad**2

    # ------------------------------------------------------------------ placing
    def add(
        self, kind: str, r: Rect, yaw: float, sid: int, against: str | None = None, gap: float = 0.1
    ) -> bool:
        """Place one item if it fits; ``against`` names the wall its back must touch."""
        H, W = self.spaces.shape
        if r.w < 1 or r.h < 1 or r.x0 < 1 or r.y0 < 1 or r.x1 >= W or r.y1 >= H:
            return False
        if not (self.spaces[r.y0 : r.y1, r.x0 : r.x1] == sid).all():
            return False
        if self.keepout[r.y0 : r.y1, r.x0 : r.x1].any():
            return False
        g = self.cells(gap) if gap > 0 else 0
        if self.mask[max(r.y0 - g, 0) : r.y1 + g, max(r.x0 - g, 0) : r.x1 + g].any():
            return False
        if against is not None:
            behind = {
                "top": self.spaces[r.y0 - 1, r.x0 : r.x1],
                "bottom": self.spaces[r.y1, r.x0 : r.x1],
                "left": self.spaces[r.y0 : r.y1, r.x0 - 1],
                "right": self.spaces[r.y0 : r.y1, r.x1],
            }[against]
            if behind.any():
                return False
        # The space's free cells stay connected iff the free cells next to the new item are
        # connected to each other; checking that within a window around the item is exact
        # when it says yes and only errs on the cautious side otherwise.
        m = self.cells(1.0)
        x0, y0, x1, y1 = max(r.x0 - m, 0), max(r.y0 - m, 0), min(r.x1 + m, W), min(r.y1 + m, H)
        new = np.zeros((y1 - y0, x1 - x0), dtype=bool)
        self.render(kind, r, new, x0, y0)
        free = (self.spaces[y0:y1, x0:x1] == sid) & ~self.mask[y0:y1, x0:x1] & ~new
        _, cc = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
        touching = cv2.dilate(new.astype(np.uint8), _CROSS).astype(bool) & free
        if np.unique(cc[touching]).size != 1:
            return False
        self.mask[y0:y1, x0:x1] |= new
        self.items.append(Item(kind, r, yaw, sid))
        return True

    def wall_rect(self, room: Rect, side: str, pos: int, length: int, depth: int) -> Rect:
        """A footprint ``length`` along ``side`` of ``room`` starting at ``pos``, ``depth`` deep."""
        if side == "top":
            return Rect(pos, room.y0, pos + length, room.y0 + depth)
        if side == "bottom":
            return Rect(pos, room.y1 - depth, pos + length, room.y1)
        if side == "left":
            return Rect(room.x0, pos, room.x0 + depth, pos + length)
        return Rect(room.x1 - depth, pos, room.x1, pos + length)

    def against_wall(
        self,
        kind: str,
        room: Rect,
        sid: int,
        length_m: float,
        depth_m: float,
        tries: int = 12,
        gap: float = 0.1,
    ) -> Item | None:
        """Put an item with its back to some wall of ``room``; returns it, or None."""
        length, depth = self.cells(length_m), self.cells(depth_m)
        for _ in range(tries):
            side = ("top", "bottom", "left", "right")[int(self.rng.integers(4))]
            lo, hi = (room.x0, room.x1) if side in ("top", "bottom") else (room.y0, room.y1)
            if hi - lo < length:
                continue
            if self.rng.random() < 0.5:
                pos = lo if self.rng.random() < 0.5 else hi - length  # tucked into a corner
            else:
                pos = int(self.rng.integers(lo, hi - length + 1))
            r = self.wall_rect(room, side, pos, length, depth)
            if self.add(kind, r, _WALL_YAW[side], sid, against=side, gap=gap):
                return self.items[-1]
        return None

    def centred(
        self, kind: str, room: Rect, sid: int, w_m: float, d_m: float, clear_m: float, tries: int = 10
    ) -> Item | None:
        """An item standing free in ``room`` at least ``clear_m`` from its walls."""
        w, h = self.cells(w_m), self.cells(d_m)
        if self.rng.random() < 0.5 and room.w < room.h:
            w, h = h, w
        c = self.cells(clear_m)
        for _ in range(tries):
            if room.w - 2 * c < w or room.h - 2 * c < h:
                return None
            x0 = int(self.rng.integers(room.x0 + c, room.x1 - c - w + 1))
            y0 = int(self.rng.integers(room.y0 + c, room.y1 - c - h + 1))
            yaw = 0.0 if w >= h else math.pi / 2
            if self.add(kind, Rect(x0, y0, x0 + w, y0 + h), yaw, sid, gap=0.3):
                return self.items[-1]
        return None

    def beside(self, kind: str, anchor: Item, size_m: float, dist_m: float, gap: float = 0.05) -> Item | None:
        """A small round item next to ``anchor`` (a chair at a desk, a bucket by a table)."""
        s, dist = self.cells(size_m), self.cells(dist_m)
        a = anchor.rect
        cands = []
        for side in ("top", "bottom", "left", "right"):
            if side in ("top", "bottom"):
                x = (a.x0 + a.x1 - s) // 2 + int(self.rng.integers(-(a.w // 4), a.w // 4 + 1))
                y = a.y0 - dist - s if side == "top" else a.y1 + dist
            else:
                y = (a.y0 + a.y1 - s) // 2 + int(self.rng.integers(-(a.h // 4), a.h // 4 + 1))
                x = a.x0 - dist - s if side == "left" else a.x1 + dist
            cands.append(Rect(x, y, x + s, y + s))
        # a chair goes in front of its desk first; otherwise any side
        order = list(self.rng.permutation(4))
        front = _front_side(anchor.yaw)
        if kind == "chair" and front is not None:
            order = [("top", "bottom", "left", "right").index(front)]
        for i in order:
            if self.add(kind, cands[int(i)], 0.0, anchor.space, gap=gap):
                return self.items[-1]
        return None


def _front_side(yaw: float) -> str | None:
    """The side of a wall item its front faces ("top" = towards the top of the image)."""
    for side, y in _WALL_YAW.items():
        if math.isclose(math.remainder(yaw - y, 2 * math.pi), 0.0, abs_tol=1e-9):
            return {"top": "bottom", "bottom": "top", "left": "right", "right": "left"}[side]
    return None


# ---------------------------------------------------------------------- recipes per room use
def _n(f: Furnisher, k: float, scale: float) -> int:
    """A count around ``k × scale`` (Poisson), for clutter density ``scale``."""
    return int(f.rng.poisson(k * scale))


def _office(f: Furnisher, room: Rect, sid: int, s: float) -> None:
    area = room.area * f.d.res**2
    for _ in range(max(1, _n(f, 1.0 + area / 10.0, s))):
        desk = f.against_wall("desk", room, sid, f.uniform(1.2, 1.8), f.uniform(0.6, 0.8))
        if desk is not None:
            f.beside("chair", desk, f.uniform(0.2, 0.3), f.uniform(0.15, 0.35))
    for _ in range(_n(f, 1.2, s)):
        f.against_wall(
            ("cabinet", "shelf")[int(f.rng.integers(2))],
            room,
            sid,
            f.uniform(0.8, 2.0),
            f.uniform(0.4, 0.6),
            gap=0.0,
        )
    if f.rng.random() < 0.3 * s:
        f.against_wall("plant", room, sid, 0.4, 0.4)


def _lab(f: Furnisher, room: Rect, sid: int, s: float) -> None:
    perim = 2 * (room.w + room.h) * f.d.res
    for _ in range(_n(f, perim / 6.0, s)):
        t = f.against_wall("table", room, sid, f.uniform(1.4, 2.4), f.uniform(0.7, 0.9))
        if t is not None and f.rng.random() < 0.7:
            f.beside("chair", t, f.uniform(0.2, 0.3), f.uniform(0.15, 0.35))
    for _ in range(_n(f, 1.0 + room.area * f.d.res**2 / 40.0, s)):
        island = f.centred("table", room, sid, f.uniform(1.6, 2.4), f.uniform(0.8, 1.2), 1.2)
        for _ in range(int(f.rng.integers(0, 4)) if island is not None else 0):
            assert island is not None
            f.beside("chair", island, f.uniform(0.2, 0.3), f.uniform(0.1, 0.3))
    for _ in range(_n(f, 1.5, s)):
        f.against_wall(
            ("shelf", "equipment", "cabinet")[int(f.rng.integers(3))],
            room,
            sid,
            f.uniform(0.6, 2.0),
            f.uniform(0.5, 0.9),
            gap=0.0,
        )


def _seminar(f: Furnisher, room: Rect, sid: int, s: float) -> None:
    res = f.d.res
    long_, short = max(room.w, room.h) * res, min(room.w, room.h) * res
    tl = min(long_ - 2 * f.uniform(1.3, 1.8), 6.0)
    tw = min(short - 2 * f.uniform(1.3, 1.8), 2.4)
    if tl >= 1.6 and tw >= 0.9:
        w, h = (f.cells(tl), f.cells(tw)) if room.w >= room.h else (f.cells(tw), f.cells(tl))
        x0 = (room.x0 + room.x1 - w) // 2 + int(f.rng.integers(-2, 3))
        y0 = (room.y0 + room.y1 - h) // 2 + int(f.rng.integers(-2, 3))
        table = Rect(x0, y0, x0 + w, y0 + h)
        if f.add("table", table, 0.0 if w >= h else math.pi / 2, sid, gap=0.3):
            _chairs_around(f, table, sid)
    for _ in range(_n(f, 0.8, s)):
        f.against_wall(
            ("cabinet", "shelf")[int(f.rng.integers(2))],
            room,
            sid,
            f.uniform(0.8, 2.0),
            f.uniform(0.4, 0.6),
            gap=0.0,
        )


def _chairs_around(f: Furnisher, t: Rect, sid: int) -> None:
    """A ring of chairs around a conference table (the dotted rectangles of real maps)."""
    s = f.cells(f.uniform(0.2, 0.28))
    off = f.cells(f.uniform(0.15, 0.3))
    step = f.cells(f.uniform(0.6, 0.8))
    for side in ("top", "bottom", "left", "right"):
        n = max(1, ((t.w if side in ("top", "bottom") else t.h) - step // 2) // step)
        for i in range(n):
            if side in ("top", "bottom"):
                x = t.x0 + (t.w - (n - 1) * step) // 2 + i * step - s // 2
                y = t.y0 - off - s if side == "top" else t.y1 + off
            else:
                y = t.y0 + (t.h - (n - 1) * step) // 2 + i * step - s // 2
                x = t.x0 - off - s if side == "left" else t.x1 + off
            f.add("chair", Rect(x, y, x + s, y + s), 0.0, sid, gap=0.05)


def _kitchen(f: Furnisher, room: Rect, sid: int, s: float) -> None:
    side_len = min(max(room.w, room.h) * f.d.res - 0.8, 3.0)
    if side_len >= 1.2:
        f.against_wall("counter", room, sid, f.uniform(1.2, side_len), 0.6, gap=0.0)
    f.against_wall("fridge", room, sid, 0.6, 0.65, gap=0.0)
    t = f.centred("table", room, sid, f.uniform(0.8, 1.2), 0.8, 0.7)
    if t is not None:
        for _ in range(int(f.rng.integers(2, 5))):
            f.beside("chair", t, f.uniform(0.2, 0.3), f.uniform(0.1, 0.3))


def _storage(f: Furnisher, room: Rect, sid: int, s: float) -> None:
    for _ in range(max(1, _n(f, 3.0, s))):
        f.against_wall("shelf", room, sid, f.uniform(0.8, 2.0), f.uniform(0.4, 0.6), gap=0.0)


def living_room(f: Furnisher, room: Rect, sid: int) -> Item | None:
    """A couch against a wall, a TV on a stand facing it, a coffee table between; returns the table."""
    couch = f.against_wall("couch", room, sid, f.uniform(1.8, 2.4), f.uniform(0.8, 0.95), tries=40)
    if couch is None:
        return None
    front = _front_side(couch.yaw)
    assert front is not None
    # the TV stands against the wall the couch faces
    opposite = front
    cx, cy = (couch.rect.x0 + couch.rect.x1) // 2, (couch.rect.y0 + couch.rect.y1) // 2
    tl, td = f.cells(f.uniform(1.0, 1.6)), f.cells(f.uniform(0.35, 0.5))
    for shift in (0, 4, -4, 8, -8, 12, -12, 20, -20):
        pos = (cx if opposite in ("top", "bottom") else cy) - tl // 2 + f.cells(0.1) * shift
        r = f.wall_rect(room, opposite, pos, tl, td)
        if f.add("tv", r, _WALL_YAW[opposite], sid, against=opposite, gap=0.1):
            break
    # the coffee table in front of the couch
    cw, cd = f.cells(f.uniform(0.8, 1.2)), f.cells(f.uniform(0.5, 0.7))
    dist = f.cells(f.uniform(0.4, 0.6))
    c = couch.rect
    if front in ("top", "bottom"):
        x0 = (c.x0 + c.x1 - cw) // 2
        y0 = c.y0 - dist - cd if front == "top" else c.y1 + dist
        r = Rect(x0, y0, x0 + cw, y0 + cd)
    else:
        y0 = (c.y0 + c.y1 - cw) // 2
        x0 = c.x0 - dist - cd if front == "left" else c.x1 + dist
        r = Rect(x0, y0, x0 + cd, y0 + cw)
    if f.add("table", r, couch.yaw, sid, gap=0.2):
        return f.items[-1]
    return f.centred("table", room, sid, 1.0, 0.6, 0.6, tries=30)


def _hall(f: Furnisher, room: Rect, sid: int, s: float) -> None:
    res = f.d.res
    if min(room.w, room.h) * res >= 7.0 and f.rng.random() < 0.7:
        step = f.cells(f.uniform(4.0, 6.0))
        size = f.cells(f.uniform(0.3, 0.5))
        m = f.cells(2.0)
        for y in range(room.y0 + m, room.y1 - m - size + 1, step):
            for x in range(room.x0 + m, room.x1 - m - size + 1, step):
                f.add("pillar", Rect(x, y, x + size, y + size), 0.0, sid, gap=0.3)
    if f.rng.random() < 0.6 * s:
        f.against_wall("counter", room, sid, f.uniform(2.0, 3.5), f.uniform(0.6, 0.8))
    for _ in range(_n(f, 1.0, s)):
        f.against_wall("couch", room, sid, f.uniform(1.6, 2.2), 0.85)
    for _ in range(_n(f, 2.0, s)):
        f.against_wall("plant", room, sid, 0.45, 0.45)


def _partition(f: Furnisher, room: Rect, sid: int) -> None:
    """A partition wall standing out from one wall (0.4–0.7 of the room across)."""
    t = f.cells(0.1)
    for _ in range(6):
        side = ("top", "bottom", "left", "right")[int(f.rng.integers(4))]
        across = room.h if side in ("top", "bottom") else room.w
        along_lo, along_hi = (room.x0, room.x1) if side in ("top", "bottom") else (room.y0, room.y1)
        length = round(across * f.uniform(0.4, 0.7))
        span = along_hi - along_lo
        pos = along_lo + round(span * f.uniform(0.35, 0.65))
        if side in ("top", "bottom"):
            r = (
                Rect(pos, room.y0, pos + t, room.y0 + length)
                if side == "top"
                else Rect(pos, room.y1 - length, pos + t, room.y1)
            )
        else:
            r = (
                Rect(room.x0, pos, room.x0 + length, pos + t)
                if side == "left"
                else Rect(room.x1 - length, pos, room.x1, pos + t)
            )
        if f.add("partition", r, _WALL_YAW[side], sid, against=side, gap=0.5):
            return


RECIPES: dict[str, Callable[[Furnisher, Rect, int, float], None]] = {
    "office": _office,
    "lab": _lab,
    "seminar": _seminar,
    "kitchen": _kitchen,
    "storage": _storage,
    "hall": _hall,
}


def furnish_room(f: Furnisher, use: str, room: Rect, sid: int, scale: float) -> None:
    """Clutter one room (or hall) after its ``use``; ``scale`` ~1 is a typical office."""
    if use in ("lab", "office") and room.area * f.d.res**2 >= 25.0 and f.rng.random() < 0.2:
        _partition(f, room, sid)
    RECIPES.get(use, _office)(f, room, sid, scale)


def furnish_corridor(f: Furnisher, rects: tuple[Rect, ...], sid: int, scale: float) -> None:
    """A few cabinets, plants and printers along corridor walls (never narrower than 1 m left)."""
    res = f.d.res
    for r in rects:
        width = min(r.w, r.h) * res
        length = max(r.w, r.h) * res
        for _ in range(_n(f, length / 15.0, scale)):
            kind = ("cabinet", "plant", "printer")[int(f.rng.integers(3))]
            depth = min(0.5, width - 1.0)
            if depth < 0.3:
                continue
            f.against_wall(
                kind,
                r,
                sid,
                0.45 if kind == "plant" else f.uniform(0.6, 1.2),
                min(depth, 0.45 if kind == "plant" else depth),
                tries=6,
            )


def corridor_item(
    f: Furnisher, kind: str, rects: tuple[Rect, ...], sid: int, w_m: float, d_m: float
) -> Item | None:
    """One item (e.g. the charging station) against a corridor wall, clear of doors."""
    for _ in range(8):
        r = rects[int(f.rng.integers(len(rects)))]
        item = f.against_wall(kind, r, sid, w_m, d_m, tries=10, gap=0.3)
        if item is not None:
            return item
    return None


def assign_uses(rng: np.random.Generator, rooms: dict[int, Rect], res: float) -> dict[int, str]:
    """What each room is used as, from its size: office, lab, seminar, kitchen or storage."""
    uses: dict[int, str] = {}
    kitchen = rng.random() < 0.6
    for sid in sorted(rooms):
        r = rooms[sid]
        area = r.area * res**2
        u = rng.random()
        if area >= 35.0:
            use = "lab" if u < 0.5 else "seminar"
        elif area >= 25.0:
            use = "seminar" if u < 0.3 else "lab" if u < 0.5 else "office"
        elif area < 9.0:
            use = "storage" if u < 0.35 else "office"
        else:
            use = "office"
        if kitchen and use == "office" and 9.0 <= area <= 25.0 and rng.random() < 0.3:
            use, kitchen = "kitchen", False
        uses[sid] = use
    return uses


def living_room_candidates(rooms: dict[int, Rect], res: float, near_corridor: set[int]) -> list[int]:
    """Rooms fit to be the living room, best first: 3.5 m wide or more, about 25 m², off a corridor."""
    ok = [sid for sid, r in rooms.items() if min(r.w, r.h) * res >= 3.5]
    return sorted(ok, key=lambda sid: (sid not in near_corridor, abs(rooms[sid].area * res**2 - 25.0), sid))


def furnish_building(
    f: Furnisher,
    rects: dict[int, tuple[Rect, ...]],
    kinds: dict[int, str],
    uses: dict[int, str],
    *,
    clutter: bool,
    density: float,
    living: list[int] | None,
    charging_station: bool,
    bucket: bool,
) -> None:
    """Furnish a whole building; ``uses`` gets "living room" for the room chosen from ``living``.

    Raises RuntimeError if a requested item (living room, charging station, bucket) finds no place.
    """
    scale = density * f.uniform(0.4, 1.2)
    coffee: Item | None = None
    if living is not None:
        for sid in living:
            coffee = living_room(f, rects[sid][0], sid)
            if coffee is not None:
                uses[sid] = "living room"
                break
        else:
            raise RuntimeError("no room of this building can hold the living room's couch, TV and table")
    if charging_station:
        corridors = sorted(
            (sid for sid, k in kinds.items() if k == "corridor"), key=lambda s: -sum(r.area for r in rects[s])
        )
        if not any(corridor_item(f, "charging_station", rects[sid], sid, 0.5, 0.35) for sid in corridors):
            raise RuntimeError("no corridor wall of this building has room for the charging station")
    if clutter and density > 0:
        p_room = min(1.0, 0.35 + 0.5 * scale)
        for sid in sorted(kinds):
            kind = kinds[sid]
            if kind == "corridor":
                furnish_corridor(f, rects[sid], sid, scale)
            elif kind == "hall":
                furnish_room(f, "hall", rects[sid][0], sid, scale)
            elif uses.get(sid) == "living room":
                f.against_wall("shelf", rects[sid][0], sid, f.uniform(0.8, 1.6), 0.4)
                f.against_wall("plant", rects[sid][0], sid, 0.45, 0.45)
            elif f.rng.random() < p_room:
                furnish_room(f, uses.get(sid, "office"), rects[sid][0], sid, scale)
    if bucket:
        living_ids = {sid for sid, u in uses.items() if u == "living room"}
        tables = [it for it in f.items if it.kind == "table" and it.space not in living_ids]
        tables += [coffee] if coffee is not None else []
        for t in tables:
            if f.beside("bucket", t, f.uniform(0.25, 0.35), f.uniform(0.15, 0.4)) is not None:
                return
        for sid in sorted(s for s, k in kinds.items() if k == "room"):
            extra = f.centred("table", rects[sid][0], sid, 1.2, 0.8, 0.8)
            if extra is not None and f.beside("bucket", extra, 0.3, 0.2) is not None:
                return
        raise RuntimeError("no table of this building has room for a bucket beside it")
