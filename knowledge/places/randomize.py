"""Domain randomisation of training data: maps and scans that look more like the real world.

``docs/results/sim_vs_real.md`` measured what separates scans cast in drawn maps from a real
laser's in the same building: real rooms are full of furniture that ends half the beams
1–1.5 m short of the drawn walls (some twenty jumps per scan where the drawing gives one or
two), about 2 % of the beams return no echo from surfaces a couple of metres away, and the
drawn maps' scale is uncertain (0.063 m per pixel for Freiburg 079 against the assumed 0.05).
This module makes training maps and scans with those properties, drawn at random:

* :func:`rescale` — the map's metres per cell times a factor (the drawing's scale error);
* :func:`add_clutter` — furniture against the walls (solid cabinets and shelves, desks shown
  by their legs), free-standing pieces, chairs and small things such as chair legs and bins,
  in rooms mostly and a little in corridors, never in front of a door;
* :func:`close_doors` — some door openings shut (a closed door is a wall to a laser);
* :func:`perturb_scans` — range noise and centimetre quantisation, runs of no-echo beams,
  and people's legs near the sensor.

Everything is a pure function of its inputs and a :class:`numpy.random.Generator`: the same
seed gives the same map and scans. Lengths are metres, maps keep their label images (cells
covered by clutter lose their label: no scan is taken inside furniture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from knowledge.metric.grid import OCCUPIED, OccupancyGrid
from knowledge.places.dataset import LabelledMap

__all__ = [
    "ClutterParams",
    "ScanNoiseParams",
    "add_clutter",
    "close_doors",
    "perturb_scans",
    "randomize_map",
    "rescale",
]


@dataclass(frozen=True)
class ClutterParams:
    """How much furniture :func:`add_clutter` puts into a map.

    Densities are expected items per square metre of the space's free area; each is drawn
    from a Poisson law.

    Attributes:
        wall: items standing against room walls (cabinets, shelves, desks).
        free: free-standing items in rooms (tables, boxes, chairs).
        small: small round things in rooms (chair legs, bins, plant pots): radius 3–8 cm.
        corridor: items against corridor walls (cabinets, bins, plants).
        legs_share: share of wall and free items drawn as four legs (tables, desks), not solid.
        door_keepout: metres around doorway cells kept clear.
        depth: (min, max) depth of wall items, metres.
        length: (min, max) length of wall items along the wall, metres.
    """

    wall: float = 0.2
    free: float = 0.06
    small: float = 0.15
    corridor: float = 0.03
    legs_share: float = 0.35
    door_keepout: float = 0.6
    depth: tuple[float, float] = (0.3, 0.9)
    length: tuple[float, float] = (0.5, 2.5)

    def __post_init__(self) -> None:
        for name in ("wall", "free", "small", "corridor", "door_keepout"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"ClutterParams.{name} must be a finite number >= 0, got {v!r}")
        if not 0.0 <= self.legs_share <= 1.0:
            raise ValueError(f"ClutterParams.legs_share is a share in [0, 1], got {self.legs_share!r}")
        for name in ("depth", "length"):
            lo, hi = getattr(self, name)
            if not (0 < lo <= hi and math.isfinite(hi)):
                raise ValueError(f"ClutterParams.{name} must be (min, max) metres with 0 < min <= max")

    def scaled(self, k: float) -> ClutterParams:
        """The same kinds of items, ``k`` times as many."""
        return ClutterParams(
            self.wall * k,
            self.free * k,
            self.small * k,
            self.corridor * k,
            self.legs_share,
            self.door_keepout,
            self.depth,
            self.length,
        )


def rescale(lmap: LabelledMap, factor: float) -> LabelledMap:
    """``lmap`` with every cell ``factor`` times as large (same cells, same labels)."""
    if not (math.isfinite(factor) and factor > 0):
        raise ValueError(f"the scale factor must be a positive number, got {factor!r}")
    g = lmap.grid
    grid = OccupancyGrid(g.state, g.resolution * factor, g.origin, g.name)
    return LabelledMap(grid, lmap.labels, lmap.names)


def _with_occupied(lmap: LabelledMap, occupied: np.ndarray, suffix: str) -> LabelledMap:
    """``lmap`` with ``occupied`` cells made occupied (and unlabelled)."""
    g = lmap.grid
    state = g.state.copy()
    state[occupied] = OCCUPIED
    labels = lmap.labels.copy()
    labels[occupied] = 0
    name = g.name if not suffix or g.name.endswith(suffix) else g.name + suffix
    return LabelledMap(OccupancyGrid(state, g.resolution, g.origin, name), labels, lmap.names)


def _code(lmap: LabelledMap, name: str) -> int | None:
    for code, n in lmap.names.items():
        if n == name:
            return int(code)
    return None


def _mask_of(lmap: LabelledMap, *names: str) -> np.ndarray:
    out = np.zeros(lmap.labels.shape, dtype=bool)
    for n in names:
        c = _code(lmap, n)
        if c is not None:
            out |= lmap.labels == c
    return out & lmap.grid.free


def add_clutter(
    lmap: LabelledMap, rng: np.random.Generator, params: ClutterParams | None = None
) -> LabelledMap:
    """``lmap`` with furniture added (see :class:`ClutterParams`); its labels follow the free cells.

    Items are axis-aligned in the grid (drawn maps' walls mostly are). A wall item stands
    against the wall nearest to a room cell next to it and reaches ``depth`` into the room; a
    legs item is its four corner legs (5 cm), as a laser at shin height sees a table. Nothing
    is put within ``door_keepout`` of a doorway cell, and room furniture stays in rooms.
    """
    prm = params or ClutterParams()
    res = lmap.grid.resolution
    free = lmap.grid.free
    room = _mask_of(lmap, "room")
    corridor = _mask_of(lmap, "corridor", "hallway")
    door = _mask_of(lmap, "doorway")
    keep_r = max(1, round(prm.door_keepout / res))
    near_door = ndimage.binary_dilation(door, structure=np.ones((3, 3), bool), iterations=keep_r) | door
    dist, (ri, ci) = ndimage.distance_transform_edt(free, return_indices=True)
    dist_m = dist * res
    paint = np.zeros(free.shape, dtype=np.uint8)
    rows, cols = free.shape

    def box(r0: float, c0: float, r1: float, c1: float, legs: bool) -> None:
        a0, a1 = sorted((round(r0), round(r1)))
        b0, b1 = sorted((round(c0), round(c1)))
        a0, b0 = max(a0, 0), max(b0, 0)
        a1, b1 = min(a1, rows - 1), min(b1, cols - 1)
        if a1 < a0 or b1 < b0:
            return
        if legs:
            leg = max(1, round(0.05 / res))
            for r in (a0, max(a0, a1 - leg + 1)):
                for c in (b0, max(b0, b1 - leg + 1)):
                    paint[r : r + leg, c : c + leg] = 1
        else:
            paint[a0 : a1 + 1, b0 : b1 + 1] = 1

    def disk(r: float, c: float, radius_m: float) -> None:
        cv2.circle(paint, (round(c), round(r)), max(0, round(radius_m / res)), 1, -1)

    def cells(mask: np.ndarray) -> np.ndarray:
        return np.argwhere(mask)

    def n_items(density: float, mask: np.ndarray) -> int:
        return int(rng.poisson(density * float(mask.sum()) * res * res))

    def against_wall(
        space: np.ndarray,
        density: float,
        depth: tuple[float, float],
        length: tuple[float, float],
        legs_share: float,
    ) -> None:
        anchors = cells(space & (dist_m <= 1.5 * res + 1e-9) & ~near_door)
        for _ in range(min(n_items(density, space), 10 * max(1, len(anchors)))):
            if not len(anchors):
                return
            r, c = anchors[rng.integers(len(anchors))]
            dr, dc = int(ri[r, c]) - r, int(ci[r, c]) - c
            d = rng.uniform(*depth) / res
            half = 0.5 * rng.uniform(*length) / res
            legs = bool(rng.random() < legs_share)
            if abs(dr) >= abs(dc):  # the wall is above or below: the item reaches down or up
                s = -1 if dr > 0 else 1
                box(r, c - half, r + s * d, c + half, legs)
            else:
                s = -1 if dc > 0 else 1
                box(r - half, c, r + half, c + s * d, legs)

    against_wall(room, prm.wall, prm.depth, prm.length, prm.legs_share)
    against_wall(corridor, prm.corridor, (0.2, 0.5), (0.3, 1.2), 0.0)
    inner = cells(room & (dist_m > 0.6) & ~near_door)
    for _ in range(n_items(prm.free, room) if len(inner) else 0):
        r, c = inner[rng.integers(len(inner))]
        kind = rng.random()
        if kind < 0.4:  # a chair
            disk(r, c, rng.uniform(0.15, 0.3))
        else:  # a table (legs) or a box / cabinet (solid)
            h, w = rng.uniform(0.4, 1.6) / res, rng.uniform(0.4, 1.0) / res
            if rng.random() < 0.5:
                h, w = w, h
            box(r - h / 2, c - w / 2, r + h / 2, c + w / 2, bool(rng.random() < prm.legs_share))
    spots = cells(room & ~near_door)
    for _ in range(n_items(prm.small, room) if len(spots) else 0):
        r, c = spots[rng.integers(len(spots))]
        disk(r, c, rng.uniform(0.03, 0.08))
    # furniture stays in its space: room items on room cells, corridor items on corridor cells
    occupied = (paint > 0) & (room | corridor) & ~near_door
    return _with_occupied(lmap, occupied, "+clutter")


def _door_line(component: np.ndarray, occupied: np.ndarray) -> np.ndarray | None:
    """The cells of a straight line across one doorway (``component``: its cells), or None.

    The wall the door is in runs through the occupied cells that touch the doorway; the line
    goes through their mean along their main axis, over the doorway's extent.
    """
    ring = ndimage.binary_dilation(component, structure=np.ones((3, 3), bool), iterations=2) & occupied
    pts = np.argwhere(ring).astype(np.float64)
    if len(pts) < 4:
        return None
    centre = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - centre).T))
    axis = vecs[:, -1]
    comp = np.argwhere(component).astype(np.float64)
    t = (comp - centre) @ axis
    out = np.zeros_like(component, dtype=np.uint8)
    a = centre + axis * (t.min() - 2)
    b = centre + axis * (t.max() + 2)
    cv2.line(out, (round(a[1]), round(a[0])), (round(b[1]), round(b[0])), 1, 2)
    return out.astype(bool)


def close_doors(lmap: LabelledMap, rng: np.random.Generator, share: float) -> LabelledMap:
    """``lmap`` with about ``share`` of its doorways shut by a line across the opening."""
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"share is a share of the doors in [0, 1], got {share!r}")
    door = _mask_of(lmap, "doorway")
    if share == 0 or not door.any():
        return lmap
    comps, n = ndimage.label(door, structure=np.ones((3, 3), bool))
    occupied = lmap.grid.state != 0
    shut = np.zeros(door.shape, dtype=bool)
    for k in range(1, n + 1):
        if rng.random() >= share:
            continue
        line = _door_line(comps == k, occupied)
        if line is not None:
            shut |= line & lmap.grid.free
    return _with_occupied(lmap, shut, "+doors") if shut.any() else lmap


@dataclass(frozen=True)
class ScanNoiseParams:
    """What :func:`perturb_scans` does to real-looking scans.

    Attributes:
        noise_std: metres, Gaussian range noise on beams with an echo.
        quantum: metres; ranges are rounded to it (0: not rounded). A SICK LMS in cm mode: 0.01.
        no_echo_runs: expected runs of no-echo beams per scan (Poisson).
        no_echo_median: median run length in beams (log-normal lengths).
        no_echo_sigma: log-normal σ of the run lengths.
        legs: probability that a scan shows one person's legs.
        legs_range: (min, max) metres from the sensor to the person.
    """

    noise_std: float = 0.015
    quantum: float = 0.01
    no_echo_runs: float = 1.7
    no_echo_median: float = 2.0
    no_echo_sigma: float = 1.3
    legs: float = 0.15
    legs_range: tuple[float, float] = (0.5, 4.0)

    def __post_init__(self) -> None:
        for name in ("noise_std", "quantum", "no_echo_runs", "no_echo_sigma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"ScanNoiseParams.{name} must be a finite number >= 0, got {v!r}")
        if not self.no_echo_median >= 1:
            raise ValueError(
                f"ScanNoiseParams.no_echo_median is a number of beams >= 1, got {self.no_echo_median!r}"
            )
        if not 0.0 <= self.legs <= 1.0:
            raise ValueError(f"ScanNoiseParams.legs is a probability, got {self.legs!r}")


def _legs(ranges: np.ndarray, angles: np.ndarray, rng: np.random.Generator, prm: ScanNoiseParams) -> None:
    """Put one person's two legs (circles of 5–8 cm radius, 10–40 cm apart) into a scan, in place."""
    d = rng.uniform(*prm.legs_range)
    bearing = rng.uniform(angles.min(), angles.max())
    sep = rng.uniform(0.1, 0.4)
    across = bearing + math.pi / 2 + rng.uniform(-0.5, 0.5)
    for side in (-0.5, 0.5):
        cx = d * math.cos(bearing) + side * sep * math.cos(across)
        cy = d * math.sin(bearing) + side * sep * math.sin(across)
        rad = rng.uniform(0.05, 0.08)
        # ray-circle intersection: t² − 2 t (u·c) + |c|² − r² = 0
        b = np.cos(angles) * cx + np.sin(angles) * cy
        disc = b * b - (cx * cx + cy * cy - rad * rad)
        hit = disc >= 0
        t = b - np.sqrt(np.where(hit, disc, 0.0))
        hit &= t > 0
        ranges[hit] = np.minimum(ranges[hit], t[hit])


def perturb_scans(
    ranges: np.ndarray,
    angles: np.ndarray,
    rng: np.random.Generator,
    *,
    max_range: float,
    params: ScanNoiseParams | None = None,
) -> np.ndarray:
    """Real-looking copies of cast scans.

    Args:
        ranges: ``(S, B)`` metres, ``max_range`` where nothing was hit.
        angles: ``(B,)`` beam angles in the sensor frame, radians.
        rng: the random generator.
        max_range: the sensor's maximum range: no-echo beams get it.
        params: what to do.

    Returns:
        ``(S, B)`` float32: legs first, then noise and quantisation on beams with an echo, then
        the no-echo runs (which replace whatever was there by ``max_range``).
    """
    prm = params or ScanNoiseParams()
    r = np.array(ranges, dtype=np.float64, copy=True)
    if r.ndim != 2 or r.shape[1] != np.shape(angles)[0]:
        raise ValueError(f"ranges must be (S, B) with B = len(angles), got {r.shape} and {np.shape(angles)}")
    a = np.asarray(angles, dtype=np.float64)
    S, B = r.shape
    for i in np.flatnonzero(rng.random(S) < prm.legs):
        _legs(r[i], a, rng, prm)
    echo = r < max_range
    if prm.noise_std > 0:
        r = np.where(echo, r + rng.normal(0.0, prm.noise_std, r.shape), r)
    if prm.quantum > 0:
        r = np.where(echo, np.round(r / prm.quantum) * prm.quantum, r)
    r = np.clip(r, 0.01, max_range)
    runs = np.asarray(rng.poisson(prm.no_echo_runs, S))
    for i in np.flatnonzero(runs):
        for _ in range(int(runs[i])):
            n = int(np.ceil(prm.no_echo_median * math.exp(prm.no_echo_sigma * rng.standard_normal())))
            start = int(rng.integers(B))
            r[i, start : start + min(n, B)] = max_range
    return r.astype(np.float32)


def randomize_map(
    lmap: LabelledMap,
    rng: np.random.Generator,
    *,
    scale: tuple[float, float] = (0.8, 1.25),
    clutter: ClutterParams | None = None,
    clutter_scale: tuple[float, float] = (0.5, 1.5),
    doors_closed: tuple[float, float] = (0.0, 0.4),
) -> LabelledMap:
    """One random variant of a labelled map: scale drawn log-uniformly from ``scale``, clutter
    ``clutter`` times a factor from ``clutter_scale``, a share of the doors from
    ``doors_closed`` shut (doors first, so the clutter keeps clear of the shut ones too)."""
    lo, hi = scale
    k = math.exp(rng.uniform(math.log(lo), math.log(hi))) if hi > lo else lo
    out = rescale(lmap, k)
    out = close_doors(out, rng, float(rng.uniform(*doors_closed)))
    base = clutter or ClutterParams()
    out = add_clutter(out, rng, base.scaled(float(rng.uniform(*clutter_scale))))
    names = dict(out.names)
    return LabelledMap(
        OccupancyGrid(out.grid.state, out.grid.resolution, out.grid.origin, f"{lmap.name}~{k:.2f}"),
        out.labels,
        names,
    )
