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

The per-beam work runs in small numba kernels (compiled on first use, cached on disk):
the agent masks every scan, so this sits on its per-scan path.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from functools import lru_cache

import numba
import numpy as np
import numpy.typing as npt

from knowledge.people.detector import SegmentDetection
from knowledge.people.segmentation import BoolArray, FloatArray
from knowledge.people.tracking import TrackState

__all__ = ["fill_masked", "free_standing", "person_beams", "tracked_legs", "unknown_masked"]

#: Unmasked beams on each side of a masked run whose end points define the wall behind it.
WALL_POINTS = 4
#: Largest distance (metres) of a side's points from their fitted line for it to count as a wall.
WALL_TOLERANCE = 0.03


def _kernel_array(a: npt.NDArray[np.generic], dtype: type[np.generic]) -> npt.NDArray[np.generic]:
    """``a`` as a writeable C-contiguous array of ``dtype`` (copied only when it is not one), so
    that every call reaches the same compiled signature of a kernel."""
    out = np.ascontiguousarray(a, dtype=dtype)
    return out if out.flags.writeable else out.copy()


def tracked_legs(
    detection: SegmentDetection,
    legs: FloatArray,
    tracks: Sequence[TrackState],
    *,
    min_travel: float,
    radius: float = 0.6,
    standing: BoolArray | None = None,
) -> BoolArray:
    """``(S,)`` bool: the person segments of ``detection`` that belong to a person who walks.

    A segment counts when its leg (``legs``: the person segments' centroids in the tracking
    frame, in order, as :attr:`~knowledge.people.pipeline.PeopleFrame.legs`) lies within
    ``radius`` metres of a confirmed track that has travelled at least ``min_travel`` metres
    from where it was born, and is not ``standing`` (``(K,)`` bool per leg, e.g. on cells the
    laser has hit for seconds, :class:`~knowledge.people.static.StaticCells`). Time is what
    tells a leg from a table leg: furniture the detector takes for legs stays where it is,
    and masking it would hide part of the room from the place classifier and the local map.
    """
    out = np.zeros(detection.is_person.shape, dtype=bool)
    walking = np.array([t.position for t in tracks if t.travelled >= min_travel], dtype=np.float64)
    if walking.size == 0 or legs.shape[0] == 0:
        return out
    d = np.hypot(legs[:, None, 0] - walking[None, :, 0], legs[:, None, 1] - walking[None, :, 1])
    near = d.min(axis=1) <= radius
    if standing is not None:
        near &= ~np.asarray(standing, dtype=bool)
    out[np.flatnonzero(detection.is_person)] = near
    return out


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
    out = np.zeros(seg.n_segments, dtype=bool)
    if seg.n_segments:
        _free_standing(
            _kernel_array(seg.index, np.intp),
            _kernel_array(seg.ranges, np.float64),
            _kernel_array(seg.start, np.intp),
            _kernel_array(seg.stop, np.intp),
            float(clearance),
            out,
        )
    return out


@numba.njit(cache=True, nogil=True)
def _side_clear(idx: np.ndarray, rr: np.ndarray, end: int, step: int, clearance: float) -> bool:
    """One side of :func:`free_standing` for the segment ending at packed point ``end``."""
    m = idx.shape[0]
    best = -np.inf
    adjacent = False
    for k in (1, 2):
        nb = end + step * k
        if 0 <= nb < m:
            if k == 1:
                adjacent = abs(idx[nb] - idx[end]) == 1
            v = rr[nb]
            if v > best or math.isnan(v):  # np.maximum: NaN wins
                best = v
    return not adjacent or best - rr[end] >= clearance


@numba.njit(cache=True, nogil=True)
def _free_standing(
    idx: np.ndarray, rr: np.ndarray, start: np.ndarray, stop: np.ndarray, clearance: float, out: np.ndarray
) -> None:
    """``out[s]`` (S,) = segment ``s`` is free-standing (see :func:`free_standing`)."""
    for s in range(start.shape[0]):
        out[s] = _side_clear(idx, rr, start[s], -1, clearance) and _side_clear(
            idx, rr, stop[s] - 1, 1, clearance
        )


def person_beams(
    detection: SegmentDetection,
    *,
    margin: int = 1,
    clearance: float | None = 0.2,
    persons: BoolArray | None = None,
) -> BoolArray:
    """``(B,)`` bool: the beams of the person segments of ``detection``, plus up to ``margin``
    beams on each side of every person segment that belong to a single-point segment
    (a mixed pixel at the leg's edge) or have no return.

    ``clearance`` (metres, None: off): only person segments that are :func:`free_standing`
    by that much are masked, so a wall's end taken for a leg keeps its beams. ``persons``
    (``(S,)`` bool, default ``detection.is_person``): the segments to mask, e.g. only the
    legs of people tracked walking (:func:`tracked_legs`).

    Raises:
        ValueError: ``margin`` is negative, ``clearance`` is negative.
    """
    if margin < 0:
        raise ValueError(f"margin must be a number of beams >= 0, got {margin}")
    if clearance is not None and not clearance >= 0:
        raise ValueError(f"clearance must be None or a distance >= 0 metres, got {clearance}")
    seg = detection.segmentation
    flags = np.asarray(detection.is_person if persons is None else persons, dtype=bool)
    if flags.shape != (seg.n_segments,):
        return seg.beam_mask(flags)  # raises: one flag per segment
    out = np.zeros(seg.n_beams, dtype=bool)
    if not flags.any():
        return out
    _person_beams(
        _kernel_array(seg.index, np.intp),
        _kernel_array(seg.ranges, np.float64),
        _kernel_array(seg.start, np.intp),
        _kernel_array(seg.stop, np.intp),
        _kernel_array(flags, np.bool_),
        0 if margin == 0 else min(operator.index(margin), seg.n_beams),  # none reaches beyond the scan
        -1.0 if clearance is None else float(clearance),
        out,
    )
    return out


@numba.njit(cache=True, nogil=True)
def _person_beams(
    idx: np.ndarray,
    rr: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    flags: np.ndarray,
    margin: int,
    clearance: float,
    out: np.ndarray,
) -> None:
    """:func:`person_beams` into ``out`` (B,) bool, all False on entry (``clearance < 0``: off)."""
    n = out.shape[0]
    core = False
    for s in range(start.shape[0]):
        if not flags[s]:
            continue
        if clearance >= 0.0 and not (
            _side_clear(idx, rr, start[s], -1, clearance) and _side_clear(idx, rr, stop[s] - 1, 1, clearance)
        ):
            continue
        for p in range(start[s], stop[s]):
            out[idx[p]] = True
            core = True
    if margin == 0 or not core:
        return
    # the margin may take no-return beams and the beams of single-point segments ("loose")
    loose = np.ones(n, dtype=np.bool_)
    for s in range(start.shape[0]):
        if stop[s] - start[s] != 1:
            for p in range(start[s], stop[s]):
                loose[idx[p]] = False
    # grown: a core beam, or a loose beam within `margin` beams of one (no wrap-around)
    grown = out.copy()
    last = -n - margin - 1  # the nearest core beam at or before j
    for j in range(n):
        if out[j]:
            last = j
        elif loose[j] and j - last <= margin:
            grown[j] = True
    nxt = 2 * n + margin + 1  # the nearest core beam at or after j
    for j in range(n - 1, -1, -1):
        if out[j]:
            nxt = j
        elif loose[j] and nxt - j <= margin:
            grown[j] = True
    # the margin must not bridge a gap wider than itself: only the runs of grown beams that
    # hold a core beam are kept (a run of loose beams is taken from its ends)
    j = 0
    while j < n:
        if not grown[j]:
            j += 1
            continue
        a = j
        keep = False
        while j < n and grown[j]:
            keep = keep or out[j]
            j += 1
        if keep:
            for q in range(a, j):
                out[q] = True


@lru_cache(maxsize=16)
def _directions(n: int, angle_min: float, angle_increment: float) -> tuple[FloatArray, FloatArray]:
    """``(cos, sin)`` ``(n,)`` of the beam angles ``angle_min + m·angle_increment`` (a scanner's
    geometry does not change from scan to scan). Private and never written to."""
    theta = angle_min + np.arange(n, dtype=np.float64) * angle_increment
    return np.cos(theta), np.sin(theta)


_NO_ANGLES = np.zeros(0)


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
    # r is np.array's own C-contiguous copy: the kernel fills it in place
    if angle_increment is None:
        cos = sin = _NO_ANGLES
    else:
        cos, sin = _directions(r.size, float(angle_min), float(angle_increment))
    _fill_runs(r, _kernel_array(m, np.bool_), float(range_max), float(range_min), bool(circular), cos, sin)
    return r


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _fill_runs(
    r: np.ndarray,
    m: np.ndarray,
    range_max: float,
    range_min: float,
    circular: bool,
    cos: np.ndarray,
    sin: np.ndarray,
) -> None:
    """:func:`fill_masked` in place on ``r`` (B,), masked beams ``m`` (B,) bool; ``cos``/``sin``
    (B,) are the beam directions, or empty without ``angle_increment``.

    Only masked beams are written and only unmasked ones are read as neighbours, so filling
    in place reads no filled value. The arithmetic repeats the plain-numpy original step by
    step (same operations in the same order, no fast-math), so the results are the same.
    """
    n = r.shape[0]
    usable = np.empty(n, dtype=np.intp)  # the unmasked beams that can be a neighbour
    nu = 0
    for j in range(n):
        v = r[j]
        if not m[j] and not math.isnan(v) and v >= range_min and v > 0.0:
            usable[nu] = j
            nu += 1
    if nu == 0:
        return
    walls = cos.shape[0] == n
    side = np.empty((2, WALL_POINTS), dtype=np.intp)  # per side, the usable beams nearest first
    n_side = np.zeros(2, dtype=np.intp)
    px = np.empty(WALL_POINTS)
    py = np.empty(WALL_POINTS)
    lines = np.empty((2, 4))  # (cx, cy, ux, uy) of the walls beside the run
    k = 0
    j = 0
    while j < n:
        if not m[j]:
            j += 1
            continue
        a = j
        while j < n and m[j]:
            j += 1
        b = j
        while k < nu and usable[k] < a:
            k += 1  # the first usable beam after the run
        ns = 0
        if k > 0 or circular:
            top = k if k > 0 else nu
            c = 0
            for q in range(top - 1, max(0, top - WALL_POINTS) - 1, -1):
                side[ns, c] = usable[q]
                c += 1
            n_side[ns] = c
            ns += 1
        if k < nu or circular:
            lo = k if k < nu else 0
            c = 0
            for q in range(lo, min(lo + WALL_POINTS, nu)):
                side[ns, c] = usable[q]
                c += 1
            n_side[ns] = c
            ns += 1
        if ns == 0:
            continue
        # the larger neighbour (no return: range_max), capped at range_max
        fallback = np.nan
        for s in range(ns):
            v = r[side[s, 0]]
            if not (math.isfinite(v) and v > 0.0 and v >= range_min and v < range_max):
                v = range_max
            if s == 0 or v > fallback:
                fallback = v
        if range_max < fallback:
            fallback = range_max
        n_lines = 0
        if walls:
            for s in range(ns):
                c = 0
                for q in range(n_side[s]):
                    i = side[s, q]
                    v = r[i]
                    if math.isfinite(v) and v > 0.0 and v >= range_min and v < range_max:
                        px[c] = v * cos[i]
                        py[c] = v * sin[i]
                        c += 1
                    elif q == 0:
                        break  # the wall must continue from the beam next to the run
                if c < 2:
                    continue
                if _side_line(px, py, c, lines[n_lines]):
                    n_lines += 1
        for i in range(a, b):
            best = np.inf
            for w in range(n_lines):
                cx, cy, ux, uy = lines[w, 0], lines[w, 1], lines[w, 2], lines[w, 3]
                t = (cx * uy - cy * ux) / (cos[i] * uy - sin[i] * ux)
                if not (math.isfinite(t) and t > 0.0) or not t > r[i]:
                    continue  # the line is not ahead, or it is in front of the legs
                if t < best:
                    best = t
            if math.isfinite(best):
                r[i] = best if best < range_max else range_max
            else:
                r[i] = fallback


@numba.njit(cache=True, nogil=True)
def _side_line(px: np.ndarray, py: np.ndarray, k: int, line: np.ndarray) -> bool:
    """``line[:] = (cx, cy, ux, uy)``, a point on and the unit direction of the line through the
    first ``k`` points ``(px, py)``; False when they are too close together or not on a line."""
    cx = 0.0
    cy = 0.0
    for i in range(k):
        cx += px[i]
        cy += py[i]
    cx /= k
    cy /= k
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for i in range(k):
        dx, dy = px[i] - cx, py[i] - cy
        sxx += dx * dx
        syy += dy * dy
        sxy += dx * dy
    # principal axis of the 2x2 scatter matrix, in closed form
    phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    ux, uy = math.cos(phi), math.sin(phi)
    lo = hi = across = 0.0
    for i in range(k):
        dx, dy = px[i] - cx, py[i] - cy
        along = dx * ux + dy * uy
        off = abs(dy * ux - dx * uy)
        if i == 0 or along > hi:  # Python's max/min: NaN only when first
            hi = along
        if i == 0 or along < lo:
            lo = along
        if i == 0 or off > across:
            across = off
    if hi - lo < 0.05:  # points within a few centimetres: no direction
        return False
    if across > WALL_TOLERANCE:
        return False
    line[0], line[1], line[2], line[3] = cx, cy, ux, uy
    return True


def unknown_masked(ranges: npt.ArrayLike, mask: npt.ArrayLike) -> FloatArray:
    """``(B,)`` float64 ranges with the masked beams set to NaN (no information)."""
    r = np.array(ranges, dtype=np.float64)
    m = np.asarray(mask, dtype=bool)
    if r.ndim != 1 or m.shape != r.shape:
        raise ValueError(f"ranges and mask must be 1-D of the same length, got {r.shape} and {m.shape}")
    r[m] = np.nan
    return r
