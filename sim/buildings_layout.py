"""Floor plans of generated office buildings: corridors, halls and strips of rooms, in cells.

A plan is made of axis-aligned rectangles in *cell* coordinates (``x`` = column, ``y`` = row,
growing downwards as in the map image; half-open ``[x0, x1) × [y0, y1)``; coordinates may be
negative, the rasteriser shifts them). Everything between the rectangles is wall. Corridors
and halls may touch each other (an open passage); any two other spaces are kept at least one
wall thickness apart, and the door placer later cuts openings through those walls.

Each layout builder lays out its corridor skeleton and the *strips* beside it: bands one
room deep along a corridor side, later cut into rooms by :func:`partition_strip`. The
arithmetic of each builder keeps every strip at a wall's distance from its neighbours.

Layouts:

``straight``
    one corridor, rooms on both sides; a hall at one end or in the middle.
``L``
    two corridor arms meeting at a right-angled corner; a hall at an arm's far end.
``T``
    a main corridor and a stem leaving it at right angles; a hall at the junction or an end.
``loop``
    a ring corridor around an inner block of rooms (with a closed core or courtyard when
    the block is deep), rooms outside the ring; a hall on the ring's outer side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

LAYOUTS: tuple[str, ...] = ("straight", "L", "T", "loop")

#: Room sizes (metres): the side along the corridor and the depth away from it.
ROOM_MIN_WIDTH = 2.5
ROOM_MAX_WIDTH = 12.0
ROOM_MIN_DEPTH = 3.0
ROOM_MAX_DEPTH = 8.0
CORRIDOR_MIN_WIDTH = 1.5
CORRIDOR_MAX_WIDTH = 3.0
#: Wall thicknesses (metres): between rooms, between a room and a corridor, outer walls.
INNER_WALL = (0.10, 0.20)
CORRIDOR_WALL = (0.15, 0.30)
OUTER_WALL = (0.25, 0.35)

SIDES: tuple[str, ...] = ("top", "bottom", "left", "right")


@dataclass(frozen=True)
class Rect:
    """Half-open cell rectangle ``[x0, x1) × [y0, y1)`` (x = column, y = row)."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def w(self) -> int:
        return self.x1 - self.x0

    @property
    def h(self) -> int:
        return self.y1 - self.y0

    @property
    def area(self) -> int:
        return max(self.w, 0) * max(self.h, 0)

    def shift(self, dx: int, dy: int) -> Rect:
        return Rect(self.x0 + dx, self.y0 + dy, self.x1 + dx, self.y1 + dy)

    def overlaps(self, other: Rect) -> bool:
        return self.x0 < other.x1 and other.x0 < self.x1 and self.y0 < other.y1 and other.y0 < self.y1


@dataclass(frozen=True)
class Strip:
    """A band of rooms one room deep.

    ``along`` is the axis the rooms follow each other on ("x" or "y"); ``front`` the side
    facing the corridor it serves (deep rooms are split into a front and a back room).
    """

    rect: Rect
    along: str
    front: str


@dataclass
class Dims:
    """Building-wide sizes, in cells (``res`` metres per cell)."""

    res: float
    corridor_width: int
    corridor_wall: int
    inner_wall: int
    outer_wall: int

    def cells(self, metres: float) -> int:
        """Metres → cells (at least one)."""
        return max(1, round(metres / self.res))


@dataclass
class Plan:
    """The output of a layout builder (before strips are cut into rooms)."""

    layout: str
    dims: Dims
    corridors: list[tuple[Rect, ...]] = field(default_factory=list)
    halls: list[Rect] = field(default_factory=list)
    strips: list[Strip] = field(default_factory=list)

    def add_strip(self, rect: Rect, along: str, front: str) -> None:
        """Keep a strip only if it can hold at least one room."""
        d = self.dims
        length = rect.w if along == "x" else rect.h
        depth = rect.h if along == "x" else rect.w
        if length >= d.cells(ROOM_MIN_WIDTH) and depth >= d.cells(ROOM_MIN_DEPTH):
            self.strips.append(Strip(rect, along, front))


def sample_dims(rng: np.random.Generator, res: float, corridor_width: float) -> Dims:
    """Wall thicknesses drawn for one building; ``corridor_width`` in metres."""
    tc = rng.uniform(*CORRIDOR_WALL)
    ti = rng.uniform(*INNER_WALL)
    to = rng.uniform(*OUTER_WALL)
    d = Dims(res, 0, 0, 0, 0)
    d.corridor_width = d.cells(corridor_width)
    d.corridor_wall = d.cells(tc)
    d.inner_wall = d.cells(ti)
    d.outer_wall = max(d.cells(to), d.corridor_wall)
    return d


def _depth(rng: np.random.Generator, d: Dims) -> int:
    """A strip depth: mostly offices (3.5–6 m), sometimes labs (6–8 m)."""
    m = rng.uniform(3.5, 6.0) if rng.random() < 0.6 else rng.uniform(6.0, ROOM_MAX_DEPTH)
    return d.cells(m)


def _room_width(rng: np.random.Generator) -> float:
    u = rng.random()
    if u < 0.45:
        return float(rng.uniform(ROOM_MIN_WIDTH, 4.0))
    if u < 0.80:
        return float(rng.uniform(4.0, 6.5))
    return float(rng.uniform(6.5, ROOM_MAX_WIDTH))


def _end_kinds(rng: np.random.Generator, n: int, hall_end: int | None) -> list[str]:
    """What closes each of ``n`` corridor ends: a plain wall, a room across it, or the hall."""
    kinds = ["room" if rng.random() < 0.45 else "wall" for _ in range(n)]
    if hall_end is not None:
        kinds[hall_end] = "hall"
    return kinds


def _cap(rng: np.random.Generator, plan: Plan, kind: str, end: str, at: int, lo: int, hi: int) -> None:
    """Close a corridor end at coordinate ``at`` (``end`` in "x-", "x+", "y-", "y+").

    ``lo``–``hi`` is the building's extent across the corridor there. A room cap is a strip
    beyond the end wall; a hall cap opens straight onto the corridor.
    """
    d = plan.dims
    tc = d.corridor_wall
    sign = 1 if end.endswith("+") else -1
    if kind == "wall":
        return
    if kind == "room":
        depth = _depth(rng, d)
        a, b = at + sign * tc, at + sign * (tc + depth)
        front = {"x+": "left", "x-": "right", "y+": "top", "y-": "bottom"}[end]
    else:
        depth = d.cells(rng.uniform(5.0, 11.0))
        a, b = at, at + sign * depth
        # a hall often juts out beyond the wings
        lo -= d.cells(rng.uniform(0.0, 3.0)) if rng.random() < 0.5 else 0
        hi += d.cells(rng.uniform(0.0, 3.0)) if rng.random() < 0.5 else 0
        front = ""
    a, b = min(a, b), max(a, b)
    rect = Rect(a, lo, b, hi) if end[0] == "x" else Rect(lo, a, hi, b)
    if kind == "room":
        plan.add_strip(rect, "y" if end[0] == "x" else "x", front)
    else:
        plan.halls.append(rect)


def _straight(rng: np.random.Generator, d: Dims, hall: bool) -> Plan:
    p = Plan("straight", d)
    w, tc = d.corridor_width, d.corridor_wall
    length = d.cells(rng.uniform(10.0, 60.0))
    dT, dB = _depth(rng, d), _depth(rng, d)
    middle = hall and length >= d.cells(20.0) and rng.random() < 0.5
    ends = _end_kinds(rng, 2, int(rng.integers(2)) if hall and not middle else None)
    s0 = tc if ends[0] == "hall" else 0
    s1 = tc if ends[1] == "hall" else 0
    top, bot = (-tc - dT, -tc), (w + tc, w + tc + dB)
    if middle:
        hl = d.cells(rng.uniform(5.0, 10.0))
        a = round(rng.uniform(0.3, 0.7) * (length - hl))
        a = min(max(a, d.cells(4.0)), length - hl - d.cells(4.0))
        p.corridors += [(Rect(0, 0, a, w),), (Rect(a + hl, 0, length, w),)]
        ext = [d.cells(rng.uniform(0.0, 3.0)) if rng.random() < 0.5 else 0 for _ in range(2)]
        p.halls.append(Rect(a, top[0] - ext[0], a + hl, bot[1] + ext[1]))
        spans = [(s0, a - tc), (a + hl + tc, length - s1)]
    else:
        p.corridors.append((Rect(0, 0, length, w),))
        spans = [(s0, length - s1)]
    for x0, x1 in spans:
        p.add_strip(Rect(x0, top[0], x1, top[1]), "x", "bottom")
        p.add_strip(Rect(x0, bot[0], x1, bot[1]), "x", "top")
    _cap(rng, p, ends[0], "x-", 0, top[0], bot[1])
    _cap(rng, p, ends[1], "x+", length, top[0], bot[1])
    return p


def _l_shape(rng: np.random.Generator, d: Dims, hall: bool) -> Plan:
    p = Plan("L", d)
    w, tc, ti = d.corridor_width, d.corridor_wall, d.inner_wall
    dT, dB, dL, dR = (_depth(rng, d) for _ in range(4))
    L1 = max(d.cells(rng.uniform(12.0, 45.0)), w + tc + dL + d.cells(4.0))
    L2 = max(d.cells(rng.uniform(10.0, 40.0)), dB + tc + ti + d.cells(4.0))
    ends = _end_kinds(rng, 2, int(rng.integers(2)) if hall else None)
    s0 = tc if ends[0] == "hall" else 0
    s1 = tc if ends[1] == "hall" else 0
    p.corridors.append((Rect(0, 0, L1, w), Rect(L1 - w, w, L1, w + L2)))
    p.add_strip(Rect(s0, -tc - dT, L1, -tc), "x", "bottom")
    p.add_strip(Rect(L1 + tc, -tc - dT, L1 + tc + dR, w + L2 - s1), "y", "left")
    p.add_strip(Rect(s0, w + tc, L1 - w - tc, w + tc + dB), "x", "top")
    p.add_strip(Rect(L1 - w - tc - dL, w + tc + dB + ti, L1 - w - tc, w + L2 - s1), "y", "right")
    _cap(rng, p, ends[0], "x-", 0, -tc - dT, w + tc + dB)
    _cap(rng, p, ends[1], "y+", w + L2, L1 - w - tc - dL, L1 + tc + dR)
    return p


def _t_shape(rng: np.random.Generator, d: Dims, hall: bool) -> Plan:
    p = Plan("T", d)
    w, tc, ti = d.corridor_width, d.corridor_wall, d.inner_wall
    dT, dBL, dBR, dSL, dSR = (_depth(rng, d) for _ in range(5))
    L = d.cells(rng.uniform(18.0, 55.0))
    L2 = max(d.cells(rng.uniform(8.0, 35.0)), max(dBL, dBR) + tc + ti + d.cells(4.0))
    margin = d.cells(6.0)
    xs = round(rng.uniform(0.25, 0.75) * L)
    xs = min(max(xs, margin), L - w - margin)
    junction = hall and rng.random() < 0.6
    ends = _end_kinds(rng, 3, int(rng.integers(3)) if hall and not junction else None)
    sL = tc if ends[0] == "hall" else 0
    sR = tc if ends[1] == "hall" else 0
    sS = tc if ends[2] == "hall" else 0
    # stem strips stay inside the main strips' extent (clear of a hall closing an end)
    dSL = min(dSL, xs - tc - sL)
    dSR = min(dSR, L - sR - xs - w - tc)
    top = (-tc - dT, -tc)
    if junction:
        a = d.cells(rng.uniform(1.0, 4.0))
        b = d.cells(rng.uniform(1.0, 4.0))
        a, b = min(a, xs - d.cells(4.0)), min(b, L - xs - w - d.cells(4.0))
        c = d.cells(rng.uniform(3.0, 8.0))
        L2 = max(L2, c + d.cells(4.0))
        ext = d.cells(rng.uniform(0.0, 3.0)) if rng.random() < 0.5 else 0
        p.halls.append(Rect(xs - a, top[0] - ext, xs + w + b, w + c))
        p.corridors += [
            (Rect(0, 0, xs - a, w),),
            (Rect(xs + w + b, 0, L, w),),
            (Rect(xs, w + c, xs + w, w + L2),),
        ]
        p.add_strip(Rect(sL, top[0], xs - a - tc, top[1]), "x", "bottom")
        p.add_strip(Rect(xs + w + b + tc, top[0], L - sR, top[1]), "x", "bottom")
        left_x1, right_x0 = xs - a - tc, xs + w + b + tc
        stem_top = w + c + tc
    else:
        p.corridors.append((Rect(0, 0, L, w), Rect(xs, w, xs + w, w + L2)))
        p.add_strip(Rect(sL, top[0], L - sR, top[1]), "x", "bottom")
        left_x1, right_x0 = xs - tc, xs + w + tc
        stem_top = w + tc
    p.add_strip(Rect(sL, w + tc, left_x1, w + tc + dBL), "x", "top")
    p.add_strip(Rect(right_x0, w + tc, L - sR, w + tc + dBR), "x", "top")
    # a stem strip starts below the bottom strip it would otherwise run into
    sl_x0, sr_x1 = xs - tc - dSL, xs + w + tc + dSR
    sl_y0 = max(stem_top, w + tc + dBL + ti) if sl_x0 < left_x1 + ti else stem_top
    sr_y0 = max(stem_top, w + tc + dBR + ti) if sr_x1 > right_x0 - ti else stem_top
    p.add_strip(Rect(sl_x0, sl_y0, xs - tc, w + L2 - sS), "y", "right")
    p.add_strip(Rect(xs + w + tc, sr_y0, sr_x1, w + L2 - sS), "y", "left")
    _cap(rng, p, ends[0], "x-", 0, top[0], w + tc + dBL)
    _cap(rng, p, ends[1], "x+", L, top[0], w + tc + dBR)
    _cap(rng, p, ends[2], "y+", w + L2, sl_x0, sr_x1)
    return p


def _loop(rng: np.random.Generator, d: Dims, hall: bool) -> Plan:
    p = Plan("loop", d)
    w, tc, ti = d.corridor_width, d.corridor_wall, d.inner_wall
    min_inner = d.cells(ROOM_MIN_DEPTH + 0.5)
    W = max(d.cells(rng.uniform(20.0, 50.0)), 2 * (w + tc) + d.cells(8.0))
    H = max(d.cells(rng.uniform(16.0, 36.0)), 2 * (w + tc) + min_inner)
    p.corridors.append(
        (Rect(0, 0, W, w), Rect(0, H - w, W, H), Rect(0, w, w, H - w), Rect(W - w, w, W, H - w))
    )
    # the inner block
    ix0, iy0, ix1, iy1 = w + tc, w + tc, W - w - tc, H - w - tc
    Hi = iy1 - iy0
    dmax, dmin = d.cells(ROOM_MAX_DEPTH), d.cells(ROOM_MIN_DEPTH)
    if Hi <= dmax:
        p.add_strip(Rect(ix0, iy0, ix1, iy1), "x", "top")
    elif Hi - ti <= 2 * dmax:
        lo, hi = max(dmin, Hi - ti - dmax), min(dmax, Hi - ti - dmin)
        d1 = int(rng.integers(lo, hi + 1))
        p.add_strip(Rect(ix0, iy0, ix1, iy0 + d1), "x", "top")
        p.add_strip(Rect(ix0, iy0 + d1 + ti, ix1, iy1), "x", "bottom")
    else:
        d1, d2 = _depth(rng, d), _depth(rng, d)
        p.add_strip(Rect(ix0, iy0, ix1, iy0 + d1), "x", "top")
        p.add_strip(Rect(ix0, iy1 - d2, ix1, iy1), "x", "bottom")
        # rooms at the ends of the middle band face the ring's sides; the rest is a closed core
        my0, my1 = iy0 + d1 + ti, iy1 - d2 - ti
        if rng.random() < 0.7:
            dl, dr = _depth(rng, d), _depth(rng, d)
            if ix0 + dl + dr + 2 * ti + d.cells(2.0) <= ix1:
                p.add_strip(Rect(ix0, my0, ix0 + dl, my1), "y", "left")
                p.add_strip(Rect(ix1 - dr, my0, ix1, my1), "y", "right")
    # rooms outside the ring, on the sides drawn
    have = {s: rng.random() < 0.8 for s in SIDES}
    dep = {s: _depth(rng, d) for s in SIDES}
    x0 = -tc - dep["left"] if have["left"] else 0
    x1 = W + tc + dep["right"] if have["right"] else W
    y0 = -tc + ti if have["top"] else 0
    y1 = H + tc - ti if have["bottom"] else H
    hall_rect = None
    if hall:
        hl = min(d.cells(rng.uniform(6.0, 12.0)), W - d.cells(4.0))
        hd = max(d.cells(rng.uniform(5.0, 10.0)), dep["bottom"] + tc)
        hx = int(rng.integers(d.cells(2.0), max(W - hl - d.cells(2.0), d.cells(2.0) + 1)))
        hall_rect = Rect(hx, H, hx + hl, H + hd)
        p.halls.append(hall_rect)
    if have["top"]:
        p.add_strip(Rect(x0, -tc - dep["top"], x1, -tc), "x", "bottom")
    if have["bottom"]:
        band = (H + tc, H + tc + dep["bottom"])
        if hall_rect is None:
            p.add_strip(Rect(x0, band[0], x1, band[1]), "x", "top")
        else:
            p.add_strip(Rect(x0, band[0], hall_rect.x0 - tc, band[1]), "x", "top")
            p.add_strip(Rect(hall_rect.x1 + tc, band[0], x1, band[1]), "x", "top")
    if have["left"]:
        p.add_strip(Rect(x0, y0, -tc, y1), "y", "right")
    if have["right"]:
        p.add_strip(Rect(W + tc, y0, x1, y1), "y", "left")
    return p


_BUILDERS = {"straight": _straight, "L": _l_shape, "T": _t_shape, "loop": _loop}


def build_plan(rng: np.random.Generator, layout: str, dims: Dims, hall: bool) -> Plan:
    """The corridor skeleton, halls and room strips of one ``layout`` (see :data:`LAYOUTS`)."""
    return _BUILDERS[layout](rng, dims, hall)


def _split_lengths(rng: np.random.Generator, length: int, gap: int, d: Dims) -> list[int]:
    """Cut ``length`` cells into room widths in [2.5, 12] m with ``gap``-cell walls between."""
    lo, hi = d.cells(ROOM_MIN_WIDTH), int(ROOM_MAX_WIDTH / d.res)
    if length < lo:
        return []
    widths: list[float] = []
    while sum(widths) + gap * len(widths) < length:
        widths.append(_room_width(rng) / d.res)
    # keep n or n-1 rooms, whichever needs the smaller stretch to fill the strip exactly
    best: list[float] | None = None
    best_err = math.inf
    for n in (len(widths), len(widths) - 1):
        if n < 1:
            continue
        room = length - gap * (n - 1)
        s = room / sum(widths[:n])
        cand = [x * s for x in widths[:n]]
        if all(lo <= x <= hi for x in cand) and abs(math.log(s)) < best_err:
            best, best_err = cand, abs(math.log(s))
    if best is None:
        n_min = math.ceil((length + gap) / (hi + gap))
        n_max = (length + gap) // (lo + gap)
        n = min(max(round((length + gap) / (float(np.mean(widths)) + gap)), n_min), n_max)
        best = [(length - gap * (n - 1)) / n] * n
    edges = np.round(np.cumsum([0.0, *(x + gap for x in best)])).astype(int)
    return [int(edges[i + 1] - edges[i] - gap) for i in range(len(best) - 1)] + [int(length - edges[-2])]


def partition_strip(rng: np.random.Generator, strip: Strip, d: Dims, split_prob: float) -> list[Rect]:
    """Cut a strip into rooms; a deep room is sometimes split into a front and a back room."""
    r = strip.rect
    ti = d.inner_wall
    along_x = strip.along == "x"
    widths = _split_lengths(rng, r.w if along_x else r.h, ti, d)
    rooms: list[Rect] = []
    pos = r.x0 if along_x else r.y0
    for wd in widths:
        room = Rect(pos, r.y0, pos + wd, r.y1) if along_x else Rect(r.x0, pos, r.x1, pos + wd)
        pos += wd + ti
        depth = room.h if along_x else room.w
        dmin = d.cells(ROOM_MIN_DEPTH)
        if depth >= 2 * dmin + ti and rng.random() < split_prob:
            k = int(rng.integers(dmin, depth - dmin - ti + 1))
            rooms += _split_depth(room, strip.front, k, ti)
        else:
            rooms.append(room)
    return rooms


def _split_depth(room: Rect, front: str, k: int, ti: int) -> list[Rect]:
    """A front room ``k`` cells deep on the ``front`` side and a back room behind it."""
    if front == "top":
        return [
            Rect(room.x0, room.y0, room.x1, room.y0 + k),
            Rect(room.x0, room.y0 + k + ti, room.x1, room.y1),
        ]
    if front == "bottom":
        return [
            Rect(room.x0, room.y1 - k, room.x1, room.y1),
            Rect(room.x0, room.y0, room.x1, room.y1 - k - ti),
        ]
    if front == "left":
        return [
            Rect(room.x0, room.y0, room.x0 + k, room.y1),
            Rect(room.x0 + k + ti, room.y0, room.x1, room.y1),
        ]
    return [Rect(room.x1 - k, room.y0, room.x1, room.y1), Rect(room.x0, room.y0, room.x1 - k - ti, room.y1)]
