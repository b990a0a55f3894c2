"""Jump-distance segmentation of a laser scan (book Sect. 8.2, App. C).

A scan is ``B`` beams ``(ρ_m, d_m)``: beam ``m`` at angle ``angle_min + m·angle_increment``
(radians, counter-clockwise from the sensor's x axis) with range ``d_m`` metres. Its end point
is ``p_m = (d_m cos ρ_m, d_m sin ρ_m)`` in the sensor frame.

A beam has *no return* when its range is not finite, ``≤ 0`` (both used by drivers for "no
echo"), below ``range_min`` (the sensor's error codes: a Hokuyo reports its errors as ranges of
1–19 mm, and a ROS ``LaserScan`` marks everything below ``range_min`` invalid), or
``≥ range_max`` (the house convention: a beam that hit nothing carries the sensor's maximum
range). Such beams have no end point and belong to no segment.

Segmentation walks the beams that have a return, in beam order, and starts a new segment
whenever the Euclidean distance between two consecutive end points exceeds ``jump`` (15 cm
in the book). "Consecutive" skips no-return beams: a dropout inside a leg does not cut it in
two, which is also how the labels of the legs data were made (leg_tracker clusters only the
beams that have a return). ``max_gap`` limits how many no-return beams in a row a segment may
span (``None``: any number; ``0``: every no-return beam ends the segment).

Segments of any size are produced; the detector only classifies those with at least two
points (Sect. 8.2).

Arrays are "packed": ``points[k]`` is the end point of beam ``index[k]``, the ``k``-th beam
with a return; segment ``i`` holds the packed points ``start[i]:stop[i]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

#: Jump distance of the book's experiments, metres.
DEFAULT_JUMP = 0.15

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]


def beam_angles(n_beams: int, angle_min: float, angle_increment: float) -> FloatArray:
    """``(n_beams,)`` float64 beam angles in radians: ``angle_min + m·angle_increment``."""
    return angle_min + np.arange(n_beams, dtype=np.float64) * angle_increment


def has_return(ranges: npt.ArrayLike, range_max: float, range_min: float = 0.0) -> BoolArray:
    """``(B,)`` bool: the beam hit something (finite, > 0, ≥ ``range_min`` and < ``range_max`` metres)."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.asarray(np.isfinite(r) & (r > 0.0) & (r >= range_min) & (r < range_max))


@dataclass(frozen=True, eq=False)
class Segmentation:
    """The segments of one scan (see the module doc for the packed layout).

    Attributes:
        n_beams: ``B``, beams in the scan.
        index: ``(M,)`` beam index of each beam with a return, increasing.
        ranges: ``(M,)`` float64 their ranges in metres.
        points: ``(M, 2)`` float64 their end points in metres in the sensor frame.
        start: ``(S,)`` first packed point of each segment (``start[0] = 0``).
        stop: ``(S,)`` one past the last packed point of each segment (``stop[-1] = M``).
        jump: the jump distance used, metres.
        angle_min: angle of beam 0, radians; angle_increment: radians between beams.
    """

    n_beams: int
    index: IntArray
    ranges: FloatArray
    points: FloatArray
    start: IntArray
    stop: IntArray
    jump: float
    angle_min: float
    angle_increment: float

    def beam_directions(self, beams: IntArray) -> FloatArray:
        """``(K, 2)`` unit vectors of beams ``beams`` (any indices, also outside ``[0, B)``)."""
        theta = self.angle_min + np.asarray(beams, dtype=np.float64) * self.angle_increment
        return np.column_stack([np.cos(theta), np.sin(theta)])

    @property
    def n_segments(self) -> int:
        return int(self.start.shape[0])

    @property
    def n_points(self) -> int:
        """``M``, beams with a return."""
        return int(self.index.shape[0])

    @property
    def sizes(self) -> IntArray:
        """``(S,)`` number of points of each segment (feature C.1)."""
        return np.asarray(self.stop - self.start)

    @property
    def point_segment(self) -> IntArray:
        """``(M,)`` the segment of each packed point."""
        return np.repeat(np.arange(self.n_segments, dtype=np.intp), self.sizes)

    def segment_points(self, i: int) -> FloatArray:
        """``(N_i, 2)`` end points of segment ``i`` in beam order, metres."""
        return self.points[self.start[i] : self.stop[i]]

    def segment_beams(self, i: int) -> IntArray:
        """``(N_i,)`` beam indices of segment ``i``."""
        return self.index[self.start[i] : self.stop[i]]

    def beam_segment(self) -> IntArray:
        """``(B,)`` the segment of each beam, −1 for no-return beams."""
        out = np.full(self.n_beams, -1, dtype=np.intp)
        out[self.index] = self.point_segment
        return out

    def centroids(self) -> FloatArray:
        """``(S, 2)`` centre of gravity of each segment's points, metres."""
        if self.n_segments == 0:
            return np.zeros((0, 2))
        return np.add.reduceat(self.points, self.start, axis=0) / self.sizes[:, None]

    def beam_mask(self, segments: npt.ArrayLike) -> BoolArray:
        """``(B,)`` bool: the beam has a return and belongs to a segment whose flag is True.

        ``segments`` is an ``(S,)`` bool array (e.g. "classified as a leg").
        """
        flags = np.asarray(segments, dtype=bool)
        if flags.shape != (self.n_segments,):
            raise ValueError(f"need one flag per segment ({self.n_segments}), got shape {flags.shape}")
        out = np.zeros(self.n_beams, dtype=bool)
        out[self.index] = flags[self.point_segment]
        return out


def segment_scan(
    ranges: npt.ArrayLike,
    angle_min: float,
    angle_increment: float,
    *,
    range_max: float,
    range_min: float = 0.0,
    jump: float = DEFAULT_JUMP,
    max_gap: int | None = None,
) -> Segmentation:
    """Split one scan ``(B,)`` (metres) into segments by the jump distance (see the module doc).

    Args:
        ranges: ``(B,)`` ranges in metres; inf, NaN, ``≤ 0``, ``< range_min`` or ``≥ range_max``
            mean no return.
        angle_min: angle of beam 0 in radians; angle_increment: radians between beams (> 0).
        range_max: the sensor's maximum range in metres.
        range_min: the sensor's minimum range in metres (shorter readings are error codes).
        jump: the jump distance in metres (> 0).
        max_gap: most no-return beams in a row a segment may span (None: no limit).
    """
    r = np.asarray(ranges, dtype=np.float64)
    if r.ndim != 1 or r.size == 0:
        raise ValueError(f"ranges must be a non-empty 1-D array of metres, got shape {r.shape}")
    if not (math.isfinite(angle_increment) and angle_increment > 0):
        raise ValueError(f"angle_increment must be > 0 radians, got {angle_increment}")
    if not math.isfinite(angle_min):
        raise ValueError(f"angle_min must be a finite angle in radians, got {angle_min}")
    if not (math.isfinite(range_max) and range_max > 0):
        raise ValueError(f"range_max must be a positive number of metres, got {range_max}")
    if not (math.isfinite(range_min) and 0 <= range_min < range_max):
        raise ValueError(f"range_min must be a number of metres in [0, range_max), got {range_min}")
    if not (math.isfinite(jump) and jump > 0):
        raise ValueError(f"jump must be a positive distance in metres (the book uses 0.15), got {jump}")
    if max_gap is not None and (int(max_gap) != max_gap or max_gap < 0):
        raise ValueError(f"max_gap must be None or a number of beams >= 0, got {max_gap!r}")
    gap = -1 if max_gap is None else min(int(max_gap), r.size)
    index, rr, points, start, stop = _segment(
        np.ascontiguousarray(r),
        float(angle_min),
        float(angle_increment),
        float(range_max),
        float(range_min),
        float(jump),
        gap,
    )
    return Segmentation(
        r.size, index, rr, points, start, stop, float(jump), float(angle_min), float(angle_increment)
    )


@numba.njit(cache=True, nogil=True)
def _segment(
    r: FloatArray,
    angle_min: float,
    angle_increment: float,
    range_max: float,
    range_min: float,
    jump: float,
    max_gap: int,
) -> tuple[IntArray, FloatArray, FloatArray, IntArray, IntArray]:  # pragma: no cover - compiled
    """The packed arrays of :class:`Segmentation` (``max_gap < 0``: no limit), in one pass."""
    index = np.empty(r.shape[0], dtype=np.intp)
    m = 0
    for b in range(r.shape[0]):
        d = r[b]
        if math.isfinite(d) and d > 0.0 and d >= range_min and d < range_max:
            index[m] = b
            m += 1
    index = index[:m].copy()
    rr = np.empty(m)
    points = np.empty((m, 2))
    for k in range(m):
        d = r[index[k]]
        theta = angle_min + float(index[k]) * angle_increment
        rr[k] = d
        points[k, 0] = d * math.cos(theta)
        points[k, 1] = d * math.sin(theta)
    brk = np.empty(m + 1, dtype=np.intp)
    brk[0] = 0
    n_seg = 1 if m > 0 else 0
    limit = jump * jump
    for k in range(1, m):
        ex = points[k, 0] - points[k - 1, 0]
        ey = points[k, 1] - points[k - 1, 1]
        if ex * ex + ey * ey > limit or (max_gap >= 0 and index[k] - index[k - 1] - 1 > max_gap):
            brk[n_seg] = k
            n_seg += 1
    start = brk[:n_seg].copy()
    stop = np.empty(n_seg, dtype=np.intp)
    stop[: n_seg - 1] = brk[1:n_seg]
    if n_seg:
        stop[n_seg - 1] = m
    return index, rr, points, start, stop
