"""Full 360° scans from a restricted field of view (Sect. 3.5).

The place model expects ``n`` beams evenly spaced over a full turn, beam ``i`` at
``i·2π/n`` in the robot frame (x forward, counter-clockwise), ranges in ``[0, max_range]``.
A front laser (e.g. a SICK LMS 2xx: 361 beams over 180° at 0.5°) covers half of them.
:func:`full_scan` builds the full scan as the book does:

1. **Front beams are resampled**: each output beam inside the sensor's field of view
   takes the real beam nearest in angle (see :data:`FRONT_MODES` for the alternative).
   Nearest, not the minimum over the output sector, because the classifier was trained
   on single rays cast at exactly ``i·2π/n`` (:func:`knowledge.metric.raycast.cast`): the
   nearest real beam is at most half an input step away (0.25° for a SICK, ≤ 4 cm across
   at 10 m), whereas a sector minimum biases every beam near an edge downwards and narrows
   openings such as doors seen obliquely. The measurement in docs/results/navigation.md
   compares both.
2. **Rear beams are cast into the sparse local map** (:class:`~knowledge.metric.local_map.LocalMap`):
   a rear beam hits a stored endpoint when the point lies ahead along the ray within
   ``hit_radius`` metres of it; the nearest hit along the ray gives the range.
3. **Rear beams that hit nothing are interpolated** from their nearest known neighbours
   on both sides, circularly (front beams and rear hits are known), linearly in the beam
   angle as the book describes.

Real beams that returned nothing (at or above the sensor's ``range_max``, or +inf) count
as ``max_range``, which is what the ray caster gives a beam that hits nothing. Invalid
readings (NaN, or below ``range_min``: dazzle, too close) carry no information and are
filled like rear beams without a hit. A sensor that already covers the full turn needs no
simulation: its beams are only resampled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from knowledge.metric.local_map import LocalMap

__all__ = [
    "FRONT_MODES",
    "FullScanParams",
    "assemble_scan",
    "full_scan",
    "output_angles",
    "resample",
    "simulate_rear",
]

TWO_PI = 2.0 * math.pi

#: How front beams are resampled: "nearest" (the real beam nearest in angle) or "min" (the
#: shortest real beam within the output beam's sector of 2π/n).
FRONT_MODES = ("nearest", "min")


@dataclass(frozen=True)
class FullScanParams:
    """What :func:`full_scan` produces and how.

    Attributes:
        n_beams: beams of the output scan (the place model's ``scan.n_beams``).
        max_range: metres; output ranges are clipped to it and beams that hit nothing carry it
            (the model's ``scan.max_range``).
        hit_radius: metres; a rear beam hits a local-map point that lies within this distance
            of the ray. About twice the local map's cell, so that a wall sampled at one point
            per cell stops every ray that crosses it.
        front: "nearest" or "min" (see :data:`FRONT_MODES`).
        min_range: metres; local-map points closer than this to the sensor are ignored (a
            hit that close would be the robot itself or noise).
    """

    n_beams: int = 360
    max_range: float = 30.0
    hit_radius: float = 0.075
    front: str = "nearest"
    min_range: float = 0.05

    def __post_init__(self) -> None:
        if isinstance(self.n_beams, bool) or int(self.n_beams) != self.n_beams or self.n_beams < 3:
            raise ValueError(f"n_beams must be an integer >= 3, got {self.n_beams!r}")
        for name in ("max_range", "hit_radius"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of metres, got {v!r}")
        if not (math.isfinite(self.min_range) and self.min_range >= 0):
            raise ValueError(f"min_range must be >= 0 metres, got {self.min_range!r}")
        if self.front not in FRONT_MODES:
            raise ValueError(f"front must be one of {', '.join(FRONT_MODES)}, got {self.front!r}")


def output_angles(n_beams: int) -> np.ndarray:
    """``(n,)`` float64 robot-frame angles of the output beams: ``i·2π/n``."""
    return np.arange(n_beams, dtype=np.float64) * (TWO_PI / n_beams)


def _clean_input(
    ranges: np.ndarray, angles: np.ndarray, range_max: float, range_min: float, max_range: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted angles, ranges with no-returns at ``max_range``, and which beams are valid."""
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    if r.ndim != 1 or a.shape != r.shape or r.size == 0:
        raise ValueError(
            f"ranges and angles must be non-empty 1-D arrays of the same length, got {r.shape} and {a.shape}"
        )
    if not np.isfinite(a).all():
        raise ValueError("beam angles must be finite radians")
    if not (math.isfinite(range_max) and range_max > 0):
        raise ValueError(f"range_max must be a positive number of metres, got {range_max!r}")
    order = np.argsort(a, kind="stable")
    a, r = a[order], r[order]
    no_return = (r >= range_max * (1.0 - 1e-6)) & ~np.isnan(r)
    valid = no_return | (np.isfinite(r) & (r >= range_min) & (r > 0.0))
    out = np.where(no_return, max_range, np.minimum(np.nan_to_num(r, nan=0.0), max_range))
    return a, out, valid


def _coverage(a: np.ndarray) -> tuple[float, float, bool]:
    """The sensor's angular extent ``[lo, hi]`` (half a step beyond the end beams) and
    whether it is a full turn."""
    step = float(np.median(np.diff(a))) if a.size > 1 else TWO_PI
    lo, hi = float(a[0]) - 0.5 * step, float(a[-1]) + 0.5 * step
    return lo, hi, hi - lo >= TWO_PI - 1e-6


def resample(
    ranges: np.ndarray,
    angles: np.ndarray,
    *,
    range_max: float,
    params: FullScanParams,
    range_min: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Front beams onto the output beams, without any simulation.

    Returns:
        ``(n_beams,)`` float64 ranges (NaN where unknown: outside the field of view, or only
        invalid readings there) and ``(n_beams,)`` bool: inside the sensor's field of view.
    """
    a, r, valid = _clean_input(ranges, angles, range_max, range_min, params.max_range)
    lo, hi, full = _coverage(a)
    phi = output_angles(params.n_beams)
    # each output angle expressed in [lo, lo + 2π)
    rel = lo + np.mod(phi - lo, TWO_PI)
    inside = np.ones(phi.size, dtype=bool) if full else rel <= hi
    out = np.full(phi.size, np.nan)
    av, rv = a[valid], r[valid]
    if av.size == 0:
        return out, inside
    if params.front == "nearest":
        # circular nearest over the valid beams (an invalid beam is skipped, not copied)
        ext_a = np.concatenate((av[-1:] - TWO_PI, av, av[:1] + TWO_PI)) if full else av
        ext_r = np.concatenate((rv[-1:], rv, rv[:1])) if full else rv
        j = np.clip(np.searchsorted(ext_a, rel), 1, max(ext_a.size - 1, 1))
        if ext_a.size == 1:
            pick = np.zeros(rel.size, dtype=np.intp)
        else:
            pick = np.where(rel - ext_a[j - 1] <= ext_a[j] - rel, j - 1, j)
        val = ext_r[pick]
        # an output beam whose nearest valid input is far (a run of invalid readings) is unknown
        step = (hi - lo) / a.size
        gap = np.abs(ext_a[pick] - rel)
        val = np.where(gap <= max(1.5 * step, 0.5 * TWO_PI / params.n_beams + 1e-12), val, np.nan)
    else:
        # the output beams whose closed sector [φ - π/n, φ + π/n] holds each valid input beam
        # (a beam on the border between two sectors belongs to both)
        pos = np.mod(av, TWO_PI) / (TWO_PI / params.n_beams)
        val = np.full(phi.size, np.inf)
        for k in (np.ceil(pos - 0.5 - 1e-9), np.floor(pos + 0.5 + 1e-9)):
            np.minimum.at(val, np.mod(k, params.n_beams).astype(np.intp), rv)
        val[np.isinf(val)] = np.nan
        # output beams with no input beam in their sector (input coarser than output): nearest
        empty = inside & np.isnan(val)
        if empty.any():
            near = resample(
                ranges,
                angles,
                range_max=range_max,
                params=FullScanParams(
                    params.n_beams, params.max_range, params.hit_radius, "nearest", params.min_range
                ),
                range_min=range_min,
            )[0]
            val[empty] = near[empty]
    out[inside] = val[inside]
    return out, inside


def simulate_rear(
    points: np.ndarray,
    beams: np.ndarray,
    params: FullScanParams,
    *,
    pose: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """Ranges of the output beams ``beams`` cast into a set of points.

    A beam hits a point that lies ahead along it within ``params.hit_radius`` of the ray;
    a far point also stops the beam nearest to it in angle, so a far wall sampled more
    sparsely than ``hit_radius`` still stops every beam aimed at it. The nearest hit along
    the beam (the point's projection onto it) gives the range.

    Args:
        points: ``(k, 2)`` points in metres, in the frame ``pose`` is given in (the robot
            frame, x forward and y left, for the default pose).
        beams: ``(m,)`` int indices of the output beams to cast (angles ``i·2π/n`` from the
            robot's heading).
        params: ``n_beams``, ``hit_radius``, ``min_range`` and ``max_range`` are used.
        pose: the robot's ``(x, y, theta)`` in the points' frame.

    Returns:
        ``(m,)`` float64 ranges along each beam to its nearest hit, NaN for no hit.
    """
    b = np.asarray(beams, dtype=np.int64)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1:] != (2,):
        raise ValueError(f"points must be an (k, 2) array of metres, got shape {pts.shape}")
    if b.size == 0 or pts.shape[0] == 0:
        return np.full(b.size, np.nan)
    if b.min() < 0 or b.max() >= params.n_beams:
        raise ValueError(f"beam indices must lie in 0..{params.n_beams - 1}")
    want = np.zeros(params.n_beams, dtype=np.bool_)
    want[b] = True
    p = np.asarray(pose, dtype=np.float64)
    # the wanted beams' arc: when it spans at most a half turn, points behind its half-plane
    # can be skipped before any trigonometry
    ang = np.sort(b) * (TWO_PI / params.n_beams)
    gaps = np.diff(np.concatenate((ang, ang[:1] + TWO_PI)))
    g = int(np.argmax(gaps))
    start, span = ang[(g + 1) % ang.size], TWO_PI - gaps[g]
    mid = start + 0.5 * span
    best = _cast_points(
        pts,
        float(p[0]),
        float(p[1]),
        float(p[2]),
        want,
        params.hit_radius,
        max(params.min_range, 1e-9),
        params.max_range,
        math.cos(mid) if span <= math.pi else 0.0,
        math.sin(mid) if span <= math.pi else 0.0,
    )
    res = best[b]
    return np.where(np.isfinite(res), res, np.nan)


@numba.njit(cache=True, nogil=True)
def _cast_points(
    xy: np.ndarray,
    px: float,
    py: float,
    theta: float,
    want: np.ndarray,
    hit_radius: float,
    min_range: float,
    max_range: float,
    ux: float,
    uy: float,
) -> np.ndarray:
    """``(n,)`` nearest hit along each wanted beam (inf: none); see :func:`simulate_rear`.

    ``(ux, uy)``: unit direction of the middle of the wanted beams when they span at most a
    half turn (points well behind it cannot be hit), else ``(0, 0)``.
    """
    n = want.size
    step = 2.0 * math.pi / n
    sin_half_step = math.sin(0.5 * step)
    best = np.full(n, np.inf)
    c, s = math.cos(theta), math.sin(theta)
    for i in range(xy.shape[0]):
        dx, dy = xy[i, 0] - px, xy[i, 1] - py
        x, y = c * dx + s * dy, -s * dx + c * dy
        d = math.hypot(x, y)
        if d < min_range or d > max_range + hit_radius:
            continue
        if x * ux + y * uy < -(hit_radius + d * sin_half_step):
            continue
        bearing = math.atan2(y, x)
        if bearing < 0.0:
            bearing += 2.0 * math.pi
        # rays at angular distance δ pass the point at d·sin δ
        half = math.asin(min(1.0, hit_radius / d))
        half = max(half, 0.5 * step)
        lo = math.ceil((bearing - half) / step)
        hi = math.floor((bearing + half) / step)
        for k in range(lo, hi + 1):
            j = k % n
            if not want[j]:
                continue
            along = min(d * math.cos(k * step - bearing), max_range)
            if along > 0.0 and along < best[j]:
                best[j] = along
    return best


def _interpolate_circular(values: np.ndarray) -> np.ndarray:
    """Fill NaNs linearly in the beam index from the known values on both sides, circularly."""
    known = np.flatnonzero(~np.isnan(values))
    if known.size == 0:
        return values
    n = values.size
    xk = np.concatenate((known - n, known, known + n)).astype(np.float64)
    yk = np.concatenate((values[known],) * 3)
    filled = np.interp(np.arange(n, dtype=np.float64), xk, yk)
    return np.where(np.isnan(values), filled, values)


def full_scan(
    ranges: np.ndarray,
    angles: np.ndarray,
    *,
    range_max: float,
    pose: np.ndarray | tuple[float, float, float] | None = None,
    local_map: LocalMap | None = None,
    params: FullScanParams | None = None,
    range_min: float = 0.0,
) -> np.ndarray:
    """The 360° scan the place model expects, from a scan of any field of view.

    Args:
        ranges: ``(m,)`` metres of the real sensor.
        angles: ``(m,)`` its beam angles in the robot frame, radians (e.g.
            ``angle_min + i·angle_increment``); the sensor sits at the robot's origin.
        range_max: the sensor's maximum range: beams at or above it returned nothing.
        pose: the robot's odometry-frame pose when the scan was taken (needed with a map).
        local_map: recent endpoints (add this scan to it first); None or empty: every rear
            beam is interpolated.
        params: output beams, maximum range, hit radius, front mode.
        range_min: readings below this are invalid.

    Returns:
        ``(params.n_beams,)`` float32 ranges in ``[0, params.max_range]``, beam ``i`` at ``i·2π/n``.
    """
    return assemble_scan(
        ranges,
        angles,
        range_max=range_max,
        pose=pose,
        local_map=local_map,
        params=params,
        range_min=range_min,
    )[0]


def assemble_scan(
    ranges: np.ndarray,
    angles: np.ndarray,
    *,
    range_max: float,
    pose: np.ndarray | tuple[float, float, float] | None = None,
    local_map: LocalMap | None = None,
    params: FullScanParams | None = None,
    range_min: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`full_scan` and which of its beams are known (not interpolated).

    Returns:
        ``(n,)`` float32 ranges and ``(n,)`` bool: measured by the sensor or hit in the local
        map. Its mean is a quality measure of the scan: right after start-up, or after a
        long stop, most rear beams are guesses, and a caller may prefer not to classify.
    """
    prm = params or FullScanParams()
    out, inside = resample(ranges, angles, range_max=range_max, params=prm, range_min=range_min)
    rear = np.flatnonzero(~inside)
    if rear.size and local_map is not None and len(local_map):
        if pose is None:
            raise ValueError("full_scan needs the robot's pose to cast rear beams into the local map")
        out[rear] = simulate_rear(local_map.points, rear, prm, pose=pose)
    known = ~np.isnan(out)
    if not known.any():
        return np.full(prm.n_beams, prm.max_range, dtype=np.float32), known
    out = _interpolate_circular(out)
    return np.clip(out, 0.0, prm.max_range).astype(np.float32), known
