"""The sparse local map of Sect. 3.5: recent beam endpoints around the robot.

The map holds the endpoints of laser beams that hit something, in the odometry frame
(metres), and only what is useful for simulating the beams a front laser cannot see:

* **bounded in space**: points farther than ``radius`` from the robot's latest pose are
  dropped;
* **bounded in time**: points not seen again for ``max_age`` seconds are dropped (odometry
  drifts, so old points stop lining up with new ones; people walk away);
* **bounded in size**: one point per ``cell`` × ``cell`` square (the newest one), and at
  most ``max_points`` points (the oldest go first);
* **cleared by what is seen through**: a stored point that a new beam passes clearly
  beyond (the beam ends more than ``clear_margin`` behind it) is dropped, so a person who
  walked away or a point misplaced by drift does not linger in front of the sensor.

Everything is vectorised over beams and points; one :meth:`LocalMap.add` of a 361-beam scan
into a full map costs a few hundred microseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["LocalMap", "LocalMapParams", "beam_endpoints", "to_robot_frame"]


@dataclass(frozen=True)
class LocalMapParams:
    """How much the local map keeps.

    Attributes:
        radius: metres around the robot's latest pose; farther points are forgotten.
        max_points: the most points kept (the oldest are dropped first).
        max_age: seconds a point survives without being seen again.
        cell: metres; one point (the newest) is kept per ``cell`` × ``cell`` square.
        clear_margin: metres; a stored point is dropped when a new beam at its bearing ends
            more than this beyond it (None: never clear).
        grazing: radians; ... unless the point lies on a surface the beam runs along: at
            least two other stored points within ``2.5 cell`` of it lie on the beam's line
            through it (within this angle of the beam's direction). A table's side seen
            end-on is passed by the beams by a hair, and nothing was seen through it (the
            wall beyond a door jamb, which the doorway detector needs, went so). None: clear
            by the beam at the bearing alone (the rule before; older recordings replay with it).
        bracket: a stored point is cleared only when the beams on both sides of its bearing
            pass beyond it. A point on an object's silhouette edge (a table's corner, a door
            jamb seen at a slant) lies between a beam that hits the object and one that just
            misses it: by the nearest beam alone it went when the miss was the nearer (a
            table's side beyond the tour's false doorway lost the cell by its corner so, and
            with it the "wall" the doorway detector needs). A person who walked away is
            still seen through by both. False: the nearest beam (the rule before; older
            recordings replay with it).
    """

    radius: float = 25.0
    max_points: int = 8000
    max_age: float = 60.0
    cell: float = 0.1
    clear_margin: float | None = 0.3
    grazing: float | None = 0.1
    bracket: bool = True

    def __post_init__(self) -> None:
        for name in ("radius", "max_age", "cell"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"LocalMapParams.{name} must be a positive finite number, got {v!r}")
        if (
            isinstance(self.max_points, bool)
            or int(self.max_points) != self.max_points
            or self.max_points < 1
        ):
            raise ValueError(f"LocalMapParams.max_points must be a positive integer, got {self.max_points!r}")
        if self.grazing is not None and not (math.isfinite(self.grazing) and 0 < self.grazing < math.pi / 2):
            raise ValueError(
                f"LocalMapParams.grazing must be radians in (0, π/2) or None, got {self.grazing!r}"
            )
        if not isinstance(self.bracket, bool):
            raise ValueError(f"LocalMapParams.bracket must be true or false, got {self.bracket!r}")
        if self.clear_margin is not None and not (
            math.isfinite(self.clear_margin) and self.clear_margin >= 0
        ):
            raise ValueError(
                f"LocalMapParams.clear_margin must be >= 0 metres or None, got {self.clear_margin!r}"
            )


def _check_pose(pose: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise ValueError(f"pose must be a finite (x [m], y [m], theta [rad]) triple, got {pose!r}")
    return p


def _check_scan(ranges: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    if r.ndim != 1 or a.shape != r.shape:
        raise ValueError(
            f"ranges and angles must be 1-D arrays of the same length, got {r.shape} and {a.shape}"
        )
    if not np.isfinite(a).all():
        raise ValueError("beam angles must be finite radians")
    return r, a


def beam_endpoints(
    ranges: np.ndarray,
    angles: np.ndarray,
    pose: np.ndarray | tuple[float, float, float],
    *,
    range_max: float,
    range_min: float = 0.0,
) -> np.ndarray:
    """World (odometry-frame) endpoints of the beams that hit something.

    Args:
        ranges: ``(n,)`` metres.
        angles: ``(n,)`` beam angles in the robot frame, radians.
        pose: the robot's ``(x, y, theta)`` in the odometry frame.
        range_max: the sensor's maximum range; beams at or beyond it hit nothing.
        range_min: readings below this (and NaN) are invalid and skipped.

    Returns:
        ``(k, 2)`` float64 endpoints of the ``k`` valid hits.
    """
    r, a = _check_scan(ranges, angles)
    p = _check_pose(pose)
    # a hit lies strictly below range_max (SICK-style "> maximum" is reported as range_max)
    hit = np.isfinite(r) & (r >= range_min) & (r > 0.0) & (r < range_max * (1.0 - 1e-6))
    rh, th = r[hit], a[hit] + p[2]
    return np.column_stack((p[0] + rh * np.cos(th), p[1] + rh * np.sin(th)))


def to_robot_frame(points: np.ndarray, pose: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """``(k, 2)`` odometry-frame points → ``(k, 2)`` robot-frame points (x forward, y left)."""
    p = _check_pose(pose)
    d = np.asarray(points, dtype=np.float64) - p[:2]
    c, s = math.cos(p[2]), math.sin(p[2])
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))


def _cell_keys(xy: np.ndarray, cell: float) -> np.ndarray:
    """One int64 per ``cell`` × ``cell`` square (column index in the high 32 bits)."""
    c = np.floor(xy / cell).astype(np.int64)
    return (c[:, 0] << 32) | (c[:, 1] & 0xFFFFFFFF)


class LocalMap:
    """A sparse map of recent beam endpoints around the robot (see the module docstring).

    Typical use, once per scan (stamps in seconds, poses in the odometry frame)::

        local_map.add(ranges, angles, pose, stamp=t, range_max=scan.range_max)
        rear = local_map.points_in_robot_frame(pose)
    """

    def __init__(self, params: LocalMapParams | None = None) -> None:
        self.params = params or LocalMapParams()
        self._xy = np.empty((0, 2), dtype=np.float64)
        self._stamp = np.empty(0, dtype=np.float64)
        self._key = np.empty(0, dtype=np.int64)
        self._pose: np.ndarray | None = None
        self._time: float | None = None
        # robot-frame points for one pose, computed on demand
        self._rel: np.ndarray | None = None
        self._rel_pose: np.ndarray | None = None

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return int(self._xy.shape[0])

    @property
    def points(self) -> np.ndarray:
        """``(N, 2)`` float64 odometry-frame points (a read-only view)."""
        v = self._xy.view()
        v.setflags(write=False)
        return v

    @property
    def stamps(self) -> np.ndarray:
        """``(N,)`` float64 seconds: when each point was last seen (a read-only view)."""
        v = self._stamp.view()
        v.setflags(write=False)
        return v

    @property
    def pose(self) -> np.ndarray | None:
        """The pose of the latest :meth:`add` (odometry frame), or None before the first."""
        return None if self._pose is None else self._pose.copy()

    def points_in_robot_frame(self, pose: np.ndarray | tuple[float, float, float]) -> np.ndarray:
        """``(N, 2)`` the points seen from ``pose``: x forward, y left, metres (read-only).

        Computed once per pose: asking again for the latest pose returns the same array.
        """
        p = _check_pose(pose)
        if self._rel is None or self._rel_pose is None or not np.array_equal(p, self._rel_pose):
            rel = to_robot_frame(self._xy, p)
            rel.setflags(write=False)
            self._rel, self._rel_pose = rel, p
            return rel
        return self._rel

    # ------------------------------------------------------------------ updates
    def clear(self) -> None:
        """Forget every point (e.g. after the odometry was reset)."""
        self._xy = np.empty((0, 2), dtype=np.float64)
        self._stamp = np.empty(0, dtype=np.float64)
        self._key = np.empty(0, dtype=np.int64)
        self._pose = None
        self._time = None
        self._rel = None
        self._rel_pose = None

    def add(
        self,
        ranges: np.ndarray,
        angles: np.ndarray,
        pose: np.ndarray | tuple[float, float, float],
        *,
        stamp: float,
        range_max: float,
        range_min: float = 0.0,
    ) -> None:
        """Add one scan's hits seen from ``pose`` at time ``stamp``, then forget what is stale.

        Args:
            ranges: ``(n,)`` metres.
            angles: ``(n,)`` beam angles in the robot frame, radians.
            pose: the robot's odometry-frame ``(x, y, theta)`` when the scan was taken.
            stamp: seconds (any epoch, but the same for every call; not decreasing).
            range_max: the sensor's maximum range: beams at it hit nothing.
            range_min: readings below this are invalid and ignored.
        """
        if not math.isfinite(stamp):
            raise ValueError(f"stamp must be finite seconds, got {stamp!r}")
        if self._time is not None and stamp < self._time - 1e-9:
            raise ValueError(
                f"stamps must not go back in time (got {stamp} after {self._time}); "
                "call clear() when a recording restarts"
            )
        p = _check_pose(pose)
        r, a = _check_scan(ranges, angles)
        prm = self.params
        new = beam_endpoints(r, a, p, range_max=range_max, range_min=range_min)
        new = new[(new[:, 0] - p[0]) ** 2 + (new[:, 1] - p[1]) ** 2 <= prm.radius**2]
        keep = np.ones(len(self), dtype=bool)
        if prm.clear_margin is not None and len(self):
            keep &= ~self._seen_through(r, a, p, range_max, range_min)
        # forget by age and distance
        keep &= self._stamp >= stamp - prm.max_age
        keep &= (self._xy[:, 0] - p[0]) ** 2 + (self._xy[:, 1] - p[1]) ** 2 <= prm.radius**2
        # one point per cell: a new point replaces the old one in its cell
        new_keys, first = np.unique(_cell_keys(new, prm.cell), return_index=True)
        new = new[first]
        if new_keys.size and keep.any():
            # new_keys is sorted (np.unique): a binary search per stored point
            j = np.minimum(np.searchsorted(new_keys, self._key), new_keys.size - 1)
            keep &= new_keys[j] != self._key
        xy = np.concatenate((self._xy[keep], new))
        st = np.concatenate((self._stamp[keep], np.full(new.shape[0], float(stamp))))
        keys = np.concatenate((self._key[keep], new_keys))
        if xy.shape[0] > prm.max_points:
            # rows are in the order they were added and stamps never decrease: the last rows
            # are the newest
            xy, st, keys = xy[-prm.max_points :], st[-prm.max_points :], keys[-prm.max_points :]
        self._xy, self._stamp, self._key = xy, st, keys
        self._pose, self._time = p, float(stamp)
        self._rel = self._rel_pose = None

    def _seen_through(
        self, r: np.ndarray, a: np.ndarray, pose: np.ndarray, range_max: float, range_min: float
    ) -> np.ndarray:
        """``(N,)`` bool: stored points that a beam of this scan passes clearly beyond."""
        assert self.params.clear_margin is not None
        order = np.argsort(a)
        a_s, r_s = a[order], r[order]
        valid = np.isfinite(r_s) & (r_s >= range_min) & (r_s > 0.0)
        if a_s.size < 2 or not valid.any():
            return np.zeros(len(self), dtype=bool)
        # a no-return beam sees through everything within the sensor's range
        beam = np.where(valid, np.minimum(np.nan_to_num(r_s, nan=0.0), range_max), 0.0)
        return _seen_through(
            self._xy,
            float(pose[0]),
            float(pose[1]),
            float(pose[2]),
            np.ascontiguousarray(a_s),
            beam,
            valid,
            0.5 * float(np.median(np.diff(a_s))),
            float(self.params.clear_margin),
            -1.0 if self.params.grazing is None else float(self.params.grazing),
            2.5 * float(self.params.cell),
            bool(self.params.bracket),
        )


@numba.njit(cache=True, nogil=True)
def _along_surface(
    xy: np.ndarray,
    i: int,
    x: float,
    y: float,
    c: float,
    s: float,
    px: float,
    py: float,
    d: float,
    reach: float,
    grazing: float,
) -> bool:
    """Whether at least two other stored points within ``reach`` of point ``i`` lie on the
    beam's line through it (within ``grazing`` radians of the beam's direction, either way):
    the beam runs along the surface they are on (world frame; ``x, y`` the point in the
    sensor frame at distance ``d``)."""
    cx, cy = xy[i, 0], xy[i, 1]
    bx, by = (c * x - s * y) / d, (s * x + c * y) / d  # the beam's direction in the world frame
    cos_g = math.cos(grazing)
    r2 = reach * reach
    n = 0
    for j in range(xy.shape[0]):
        if j == i:
            continue
        dx, dy = xy[j, 0] - cx, xy[j, 1] - cy
        q = dx * dx + dy * dy
        if q <= 1e-12 or q > r2:
            continue
        if abs(dx * bx + dy * by) >= cos_g * math.sqrt(q):
            n += 1
            if n >= 2:
                return True
    return False


@numba.njit(cache=True, nogil=True)
def _seen_through(
    xy: np.ndarray,
    px: float,
    py: float,
    theta: float,
    angles: np.ndarray,
    ranges: np.ndarray,
    valid: np.ndarray,
    half_step: float,
    margin: float,
    grazing: float,
    reach: float,
    bracket: bool,
) -> np.ndarray:
    """Points whose nearest beam (sorted ``angles``) is valid and ends ``margin`` beyond them
    — with ``bracket``, both beams on either side of the point's bearing — unless
    (``grazing`` > 0) the beam runs along a surface through the point (:func:`_along_surface`)."""
    out = np.zeros(xy.shape[0], dtype=np.bool_)
    longest = 0.0
    for j in range(ranges.size):
        if valid[j] and ranges[j] > longest:
            longest = ranges[j]
    c, s = math.cos(theta), math.sin(theta)
    a0, a1 = angles[0], angles[-1]
    two_pi = 2.0 * math.pi
    # a field of view of at most a half turn: points behind its half-plane are skipped cheaply
    narrow = a1 - a0 + 2.0 * half_step <= math.pi + 1e-9
    mid = 0.5 * (a0 + a1)
    ux, uy = math.cos(mid), math.sin(mid)
    for i in range(xy.shape[0]):
        dx, dy = xy[i, 0] - px, xy[i, 1] - py
        x, y = c * dx + s * dy, -s * dx + c * dy
        if narrow and x * ux + y * uy < 0.0:
            continue
        d = math.hypot(x, y)
        if d + margin >= longest:
            continue
        # the bearing in [a0, a0 + 2π)
        b = a0 + ((math.atan2(y, x) - a0) % two_pi)
        if b > a1 + half_step:
            continue
        j = np.searchsorted(angles, b)
        if j <= 0:
            k = 0
        elif j >= angles.size:
            k = angles.size - 1
        else:
            k = j - 1 if b - angles[j - 1] <= angles[j] - b else j
        if not (valid[k] and ranges[k] > d + margin):
            continue
        if bracket and 0 < j < angles.size:
            o = j if k == j - 1 else j - 1  # the beam on the point's other side
            if not (valid[o] and ranges[o] > d + margin):
                continue
        if grazing > 0.0 and _along_surface(xy, i, x, y, c, s, px, py, d, reach, grazing):
            continue
        out[i] = True
    return out
