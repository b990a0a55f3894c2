"""Which beams of a scan hit people, and the scan without them (for the place classifier).

A person walking near the robot puts two small, near obstacles into the scan. The place
model was trained on empty buildings, so a corridor with a person a metre ahead looks
like a cluttered room to it, and a mapper would take the legs for walls. The agent
therefore hides the beams of detected legs from everything that models the building:

* :func:`person_beams` — ``(B,)`` bool, the beams of the segments the leg detector
  classified as person, widened by ``margin`` beams into neighbouring *single-point*
  segments (a real laser's mixed pixels at a leg's edge: an end point between the leg
  and what is behind it, too far from both to join either segment);
* :func:`fill_masked` — the ranges with each masked run of beams replaced by the **larger**
  range of the nearest unmasked beams on its two sides (a beam without a return counts as
  ``range_max``). A person stands in front of something, so the farther neighbour is the
  background the legs hide; the nearer one may be the other leg, or furniture. This is
  what the classifier sees;
* :func:`unknown_masked` — the ranges with the masked beams set to NaN: no information,
  neither a hit nor a beam that passed through (what the local map stores: it must not
  invent walls where the legs were, nor erase the wall behind them).

Ranges are metres; beam ``m`` of a ``(B,)`` scan is at ``angle_min + m·angle_increment``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from knowledge.people.detector import SegmentDetection
from knowledge.people.segmentation import BoolArray, FloatArray, has_return

__all__ = ["fill_masked", "free_standing", "person_beams", "unknown_masked"]


def free_standing(detection: SegmentDetection, clearance: float) -> BoolArray:
    """``(S,)`` bool: the segment is seen in front of what lies beside it on **both** sides.

    On each side of the segment, the farther of the next two beams with a return (two, to
    step over a mixed pixel) must be at least ``clearance`` metres farther than the
    segment's end beam on that side; a side whose next beam has no return, or the scan's
    edge, counts as clear. A leg stands in front of the background; a wall's end (a door
    jamb seen from the corridor, which the leg detector often takes for a leg) continues
    into the wall beside it at about the same range.
    """
    seg = detection.segmentation
    idx, rr = seg.index, seg.ranges
    m = seg.n_points
    first, last = seg.start, seg.stop - 1

    def side_clear(end: npt.NDArray[np.intp], step: int) -> BoolArray:
        ok = np.ones(end.shape, dtype=bool)
        best = np.full(end.shape, -np.inf)
        adjacent = np.zeros(end.shape, dtype=bool)
        for k in (1, 2):
            nb = end + step * k
            inside = (nb >= 0) & (nb < m)
            nbc = np.clip(nb, 0, max(m - 1, 0))
            if k == 1:
                adjacent = inside & (np.abs(idx[nbc] - idx[end]) == 1)
            best = np.where(inside, np.maximum(best, rr[nbc]), best)
        ok = ~adjacent | (best - rr[end] >= clearance)
        return ok

    if seg.n_segments == 0:
        return np.zeros(0, dtype=bool)
    return side_clear(first, -1) & side_clear(last, 1)


def person_beams(detection: SegmentDetection, *, margin: int = 1, clearance: float | None = 0.2) -> BoolArray:
    """``(B,)`` bool: the beams of the person segments of ``detection``, plus up to ``margin``
    beams on each side of every person segment that belong to a single-point segment
    (a mixed pixel at the leg's edge) or have no return.

    ``clearance`` (metres, None: off): only person segments that are :func:`free_standing`
    by that much are masked, so a wall's end taken for a leg keeps its beams.

    Raises:
        ValueError: ``margin`` is negative, ``clearance`` is negative.
    """
    if margin < 0:
        raise ValueError(f"margin must be a number of beams >= 0, got {margin}")
    if clearance is not None and not clearance >= 0:
        raise ValueError(f"clearance must be None or a distance >= 0 metres, got {clearance}")
    seg = detection.segmentation
    flags = detection.is_person
    if clearance is not None and flags.any():
        flags = flags & free_standing(detection, clearance)
    mask = seg.beam_mask(flags)
    if margin == 0 or not mask.any():
        return mask
    owner = seg.beam_segment()  # (B,) segment of each beam, −1 without a return
    sizes = seg.sizes
    loose = np.ones(seg.n_beams, dtype=bool)  # beams the margin may take
    has = owner >= 0
    loose[has] = sizes[owner[has]] == 1
    grown = mask.copy()
    n = seg.n_beams
    for shift in range(1, margin + 1):
        left = np.zeros(n, dtype=bool)
        left[:-shift] = mask[shift:]  # beam m is `shift` beams before a person beam
        right = np.zeros(n, dtype=bool)
        right[shift:] = mask[:-shift]
        grown |= (left | right) & loose
    # the margin must not bridge a gap wider than itself: only beams adjacent to the grown
    # region through loose beams are kept (a run of loose beams is taken from its ends)
    return _connected(grown, mask)


def _connected(grown: BoolArray, core: BoolArray) -> BoolArray:
    """The beams of ``grown`` in a run of ``grown`` that contains a ``core`` beam."""
    if grown.all() or not grown.any():
        return grown
    edges = np.flatnonzero(np.diff(grown.astype(np.int8)))
    starts = np.concatenate(([0], edges + 1))
    stops = np.concatenate((edges + 1, [grown.size]))
    out = np.zeros_like(grown)
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        if grown[a] and core[a:b].any():
            out[a:b] = True
    return out


def _runs(mask: BoolArray) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Start and stop (exclusive) of every run of True in ``mask``."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(d == 1).astype(np.intp), np.flatnonzero(d == -1).astype(np.intp)


#: Unmasked beams on each side of a masked run whose end points define the wall behind it.
WALL_POINTS = 4
#: Largest distance (metres) of a side's points from their fitted line for it to count as a wall.
WALL_TOLERANCE = 0.03


def _side_line(xs: list[float], ys: list[float]) -> tuple[float, float, float, float] | None:
    """``(cx, cy, ux, uy)``: a point on and the unit direction of the line through the points
    ``(xs[i], ys[i])``, or None when they are too few, too close together or not on a line.
    (Plain floats: a handful of points per call, where numpy's overhead would dominate.)"""
    k = len(xs)
    if k < 2:
        return None
    cx, cy = sum(xs) / k, sum(ys) / k
    dx = [x - cx for x in xs]
    dy = [y - cy for y in ys]
    sxx = sum(v * v for v in dx)
    syy = sum(v * v for v in dy)
    sxy = sum(u * v for u, v in zip(dx, dy, strict=True))
    # principal axis of the 2x2 scatter matrix, in closed form
    phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    ux, uy = math.cos(phi), math.sin(phi)
    along = [u * ux + v * uy for u, v in zip(dx, dy, strict=True)]
    if max(along) - min(along) < 0.05:  # points within a few centimetres: no direction
        return None
    if max(abs(v * ux - u * uy) for u, v in zip(dx, dy, strict=True)) > WALL_TOLERANCE:
        return None
    return cx, cy, ux, uy


def _hit_line(cos: FloatArray, sin: FloatArray, line: tuple[float, float, float, float]) -> FloatArray:
    """``(k,)`` range along rays from the origin with directions ``(cos, sin)`` to the line
    (inf: the line is not ahead)."""
    cx, cy, ux, uy = line
    den = cos * uy - sin * ux  # cross(ray, u)
    num = cx * uy - cy * ux  # cross(c, u)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    return np.where(np.isfinite(t) & (t > 0), t, np.inf)


def fill_masked(
    ranges: npt.ArrayLike,
    mask: npt.ArrayLike,
    *,
    range_max: float,
    range_min: float = 0.0,
    circular: bool = False,
    angle_min: float = 0.0,
    angle_increment: float | None = None,
) -> FloatArray:
    """``(B,)`` float64 ranges with every run of masked beams replaced by what the person hid.

    Without ``angle_increment``: the larger range of the nearest unmasked beams on both
    sides (see the module doc). With it (beam ``m`` at ``angle_min + m·angle_increment``
    radians), the walls beside the run are continued behind it: on each side the end points
    of the :data:`WALL_POINTS` nearest unmasked beams, when they lie on a line, define a
    wall, and a masked beam takes the nearer of the walls it meets beyond its measured
    range (looking down a corridor past a person, the two side walls meet far away, not at
    the range of the beams beside the legs); a beam meeting neither keeps the larger
    neighbour, capped at ``range_max``.

    Neighbours without a return count as ``range_max``; invalid ones (NaN, below
    ``range_min``) are skipped. ``circular``: the scan covers the full turn, so the first and
    the last beam are neighbours. A run with no unmasked neighbour at all keeps its ranges.

    Raises:
        ValueError: ``ranges`` and ``mask`` differ in shape.
    """
    r = np.array(ranges, dtype=np.float64)
    m = np.asarray(mask, dtype=bool)
    if r.ndim != 1 or m.shape != r.shape:
        raise ValueError(f"ranges and mask must be 1-D of the same length, got {r.shape} and {m.shape}")
    if not m.any():
        return r
    with np.errstate(invalid="ignore"):
        usable = ~m & ~np.isnan(r) & (r >= range_min) & (r > 0.0)
    hit = has_return(r, range_max, range_min)
    value = np.where(hit, r, range_max)
    idx = np.flatnonzero(usable)
    if idx.size == 0:
        return r
    n = r.size
    cos = sin = px = py = None
    if angle_increment is not None:
        theta = angle_min + np.arange(n, dtype=np.float64) * angle_increment
        cos, sin = np.cos(theta), np.sin(theta)
        with np.errstate(invalid="ignore"):
            px, py = r * cos, r * sin
    starts, stops = _runs(m)
    out = r.copy()
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        k = int(np.searchsorted(idx, a))  # first usable beam at or after a (it is >= b)
        sides: list[npt.NDArray[np.intp]] = []
        if k > 0:
            sides.append(idx[max(0, k - WALL_POINTS) : k][::-1])
        elif circular:
            sides.append(idx[-WALL_POINTS:][::-1])
        if k < idx.size:
            sides.append(idx[k : k + WALL_POINTS])
        elif circular:
            sides.append(idx[:WALL_POINTS])
        if not sides:
            continue
        fallback = min(max(float(value[s[0]]) for s in sides), range_max)
        fill = np.full(b - a, fallback)
        if cos is not None and sin is not None and px is not None and py is not None:
            best = np.full(b - a, np.inf)
            for side in sides:
                if not hit[side[0]]:  # the wall must continue from the beam next to the run
                    continue
                side = side[hit[side]]
                if side.size < 2:
                    continue
                line = _side_line(px[side].tolist(), py[side].tolist())
                if line is None:
                    continue
                t = _hit_line(cos[a:b], sin[a:b], line)
                t = np.where(t > r[a:b], t, np.inf)  # behind the legs, not in front of them
                best = np.minimum(best, t)
            fill = np.where(np.isfinite(best), np.minimum(best, range_max), fill)
        out[a:b] = fill
    return out


def unknown_masked(ranges: npt.ArrayLike, mask: npt.ArrayLike) -> FloatArray:
    """``(B,)`` float64 ranges with the masked beams set to NaN (no information)."""
    r = np.array(ranges, dtype=np.float64)
    m = np.asarray(mask, dtype=bool)
    if r.ndim != 1 or m.shape != r.shape:
        raise ValueError(f"ranges and mask must be 1-D of the same length, got {r.shape} and {m.shape}")
    r[m] = np.nan
    return r
