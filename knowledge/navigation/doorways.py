"""Detecting that the robot passes through a narrow opening (a doorway, Sect. 7.2.2).

Each scan, :func:`measure_opening` looks at the obstacle points around the robot (robot
frame, x forward, y left, metres): the points beside the robot (``|x| <= band``) on its
left and on its right, and the closest left/right pair among them. That pair is the
opening's two jambs when

* their distance (the opening's **width**) lies in ``[min_width, max_width]``;
* the robot stands between them (its projection falls on the segment between the jambs);
* **walls continue outwards** from both jambs: each side has obstacle points beyond its
  jamb, along the line through the jambs (``wall_extent`` metres of it without a gap
  longer than ``wall_gap``, within ``wall_depth`` of that line). A door is a gap in a wall; a table leg, a chair or a
  cabinet beside the path is an isolated obstacle with nothing behind it in that line
  (its back is hidden), so passing between furniture is not taken for a door.

:class:`DoorwayDetector` runs this per scan with hysteresis: the robot *enters* an opening
at the first narrow measurement, stays in it while it still finds a narrow pair of jambs
around it near the same place (the width may grow by ``hysteresis`` metres), and on
leaving it reports one :class:`Doorway`
— at the narrowest measurement — if walls were seen beyond the jambs at some
measurement (from the middle of an opening they hide behind the jambs, and a door beside a
room's corner shows its wall on one side only) and the robot crossed the line between the
jambs (from one side of the wall to the other: the line through the narrowest measurement or
through the first) within ``max_depth`` metres of travel. Approaching a
door and turning back, or driving along a long narrow passage, gives none.

The input points are best the local map's (:meth:`LocalMap.points_in_robot_frame
<knowledge.metric.local_map.LocalMap.points_in_robot_frame>`, which holds the current scan
after :meth:`~knowledge.metric.local_map.LocalMap.add`): with a front laser, the wall
around a door is behind the robot while it passes and only the local map still has it.
Never use interpolated beams of a :func:`~knowledge.metric.rear_beams.full_scan` here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from knowledge.metric.local_map import to_robot_frame

__all__ = ["Doorway", "DoorwayDetector", "DoorwayParams", "Opening", "measure_opening", "scan_points"]


@dataclass(frozen=True)
class DoorwayParams:
    """Thresholds of the doorway detector (metres).

    Attributes:
        min_width, max_width: the widths that count as a door (the robot must fit, a
            corridor must not: generated corridors are >= 1.5 m, doors 0.8–1.2 m).
        band: points with ``|x| <= band`` (beside the robot) are candidate jambs.
        hysteresis: while inside an opening, the width may grow to ``max_width + hysteresis``.
        wall_extent: metres of wall required beyond each jamb, outwards along the jamb line.
        wall_gap: the longest gap (metres) between the points of that wall: a wall is
            continuous, a row of table legs is not.
        wall_depth: how far (along the door's normal) wall points may lie from the jamb line:
            half a thick wall plus the jambs' own depth.
        max_depth: metres of travel inside the opening, beyond which it is a passage, not a door.
        same_opening: metres; a measurement whose centre lies farther than this from the
            narrowest one or from the first one belongs to another opening (the first is left).
        max_step: metres of travel between two measurements; a longer step between two
            scans is measured at poses in between (:meth:`DoorwayDetector.update`).
    """

    min_width: float = 0.5
    max_width: float = 1.3
    band: float = 0.35
    hysteresis: float = 0.15
    wall_extent: float = 0.2
    wall_gap: float = 0.15
    wall_depth: float = 0.45
    max_depth: float = 1.6
    same_opening: float = 0.5
    max_step: float = 0.25

    def __post_init__(self) -> None:
        for name in (
            "min_width",
            "max_width",
            "band",
            "wall_extent",
            "wall_gap",
            "wall_depth",
            "max_depth",
            "same_opening",
            "max_step",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"DoorwayParams.{name} must be a positive number of metres, got {v!r}")
        if not self.min_width < self.max_width:
            raise ValueError(
                f"DoorwayParams.min_width ({self.min_width}) must be below max_width ({self.max_width})"
            )
        if not (math.isfinite(self.hysteresis) and self.hysteresis >= 0):
            raise ValueError(f"DoorwayParams.hysteresis must be >= 0 metres, got {self.hysteresis!r}")


@dataclass(frozen=True)
class Opening:
    """One scan's measurement of the opening the robot stands in (robot frame).

    Attributes:
        left, right: ``(x, y)`` of the left and right jamb points, metres.
        width: their distance, metres.
        center: ``(x, y)`` midway between them.
        normal: unit ``(x, y)`` perpendicular to the jamb line, pointing forwards (+x side).
        offset: signed distance of the robot from the jamb line along ``normal`` (negative:
            before the line), metres.
        walls: whether walls continue outwards from both jambs (visible from outside the
            opening; from its middle the walls hide behind the jambs).
    """

    left: tuple[float, float]
    right: tuple[float, float]
    width: float
    center: tuple[float, float]
    normal: tuple[float, float]
    offset: float
    walls: bool


@dataclass(frozen=True)
class Doorway:
    """A doorway the robot passed through, in the odometry frame.

    Attributes:
        center: ``(x, y)`` metres, midway between the jambs at the narrowest measurement.
        width: the narrowest width measured, metres.
        orientation: radians, direction of the normal through the opening, pointing the way
            the robot passed (from the side it came from to the side it went to).
        stamp: seconds, when the narrowest measurement was taken.
    """

    center: tuple[float, float]
    width: float
    orientation: float
    stamp: float


def scan_points(
    ranges: np.ndarray, angles: np.ndarray, *, range_max: float, range_min: float = 0.0
) -> np.ndarray:
    """``(k, 2)`` robot-frame endpoints of the beams that hit something (x forward, y left)."""
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    if r.ndim != 1 or a.shape != r.shape:
        raise ValueError(f"ranges and angles must be 1-D of the same length, got {r.shape} and {a.shape}")
    hit = np.isfinite(r) & (r > 0.0) & (r >= range_min) & (r < range_max * (1.0 - 1e-6))
    return np.column_stack((r[hit] * np.cos(a[hit]), r[hit] * np.sin(a[hit])))


def _has_wall(
    pts: np.ndarray, jamb: np.ndarray, outward: np.ndarray, normal: np.ndarray, prm: DoorwayParams
) -> bool:
    """Whether obstacle points continue from ``jamb`` along ``outward`` for ``wall_extent``
    metres without a gap longer than ``wall_gap``."""
    d = pts - jamb
    along = d @ outward
    across = np.abs(d @ normal)
    sel = (along > 0.0) & (along <= prm.wall_extent + prm.wall_gap) & (across <= prm.wall_depth)
    a = np.sort(along[sel])
    if a.size == 0 or a[-1] < prm.wall_extent:
        return False
    a = a[: int(np.searchsorted(a, prm.wall_extent)) + 1]
    return bool(np.diff(a, prepend=0.0).max() <= prm.wall_gap)


def measure_opening(points: np.ndarray, params: DoorwayParams | None = None) -> Opening | None:
    """The narrow opening the robot stands in, or None (see the module docstring).

    The result's ``walls`` tells whether it is door-like (walls beyond both jambs).

    Args:
        points: ``(k, 2)`` obstacle points in the robot frame (x forward, y left), metres.
        params: thresholds.
    """
    prm = params or DoorwayParams()
    return _measure(np.asarray(points, dtype=np.float64), prm, prm.max_width)


def _measure(pts: np.ndarray, prm: DoorwayParams, max_width: float) -> Opening | None:
    if pts.ndim != 2 or pts.shape[1:] != (2,):
        raise ValueError(f"points must be an (k, 2) array of robot-frame x, y in metres, got {pts.shape}")
    reach = max_width + prm.wall_extent + 0.5
    pts = pts[(np.abs(pts[:, 0]) <= reach) & (np.abs(pts[:, 1]) <= reach)]
    side = np.abs(pts[:, 0]) <= prm.band
    left = pts[side & (pts[:, 1] > 0.0) & (pts[:, 1] <= max_width)]
    right = pts[side & (pts[:, 1] < 0.0) & (pts[:, 1] >= -max_width)]
    if left.shape[0] == 0 or right.shape[0] == 0:
        return None
    d2 = ((left[:, None, :] - right[None, :, :]) ** 2).sum(axis=2)
    i, j = np.unravel_index(int(np.argmin(d2)), d2.shape)
    pl, pr = left[i], right[j]
    width = math.sqrt(float(d2[i, j]))
    if not prm.min_width <= width <= max_width:
        return None
    u = (pl - pr) / width  # along the opening, towards the left jamb
    t = float(-pr @ u) / width  # where the robot projects on the segment right → left
    if not 0.0 < t < 1.0:
        return None
    normal = np.array([u[1], -u[0]])  # u rotated by -90°: forwards for a robot facing through
    walls = _has_wall(pts, pl, u, normal, prm) and _has_wall(pts, pr, -u, normal, prm)
    center = 0.5 * (pl + pr)
    return Opening(
        left=(float(pl[0]), float(pl[1])),
        right=(float(pr[0]), float(pr[1])),
        width=width,
        center=(float(center[0]), float(center[1])),
        normal=(float(normal[0]), float(normal[1])),
        offset=float(-center @ normal),
        walls=walls,
    )


def _to_world(pose: np.ndarray, xy: tuple[float, float]) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * xy[0] - s * xy[1], pose[1] + s * xy[0] + c * xy[1]])


@dataclass
class _Passage:
    entry: np.ndarray  # robot position (odometry frame) at entry
    center: np.ndarray  # narrowest opening's centre (odometry frame)
    normal: np.ndarray  # its normal (odometry frame, unit)
    width: float
    stamp: float
    walls: bool  # walls beyond the jambs were seen at some measurement
    travelled: float = 0.0
    anchor: np.ndarray | None = None  # the first measurement's centre

    def same(self, other: _Passage, tolerance: float) -> bool:
        """Whether a measurement lies at this opening: near its narrowest and its first centre."""
        first = self.center if self.anchor is None else self.anchor
        near = float(np.hypot(*(other.center - self.center)))
        return near <= tolerance and float(np.hypot(*(other.center - first))) <= tolerance


class DoorwayDetector:
    """Per-scan doorway detection with hysteresis (see the module docstring).

    Call :meth:`update` once per scan with the obstacle points around the robot (robot
    frame) and the robot's odometry-frame pose; it returns a :class:`Doorway` on the scan
    where the robot leaves an opening it passed through, else None. :attr:`passing` tells
    whether the robot is inside a door-like opening now (the navigation graph drops no
    place node there).
    """

    def __init__(self, params: DoorwayParams | None = None) -> None:
        self.params = params or DoorwayParams()
        self._passage: _Passage | None = None
        self._last: np.ndarray | None = None
        self._last_pose: np.ndarray | None = None
        self._last_stamp = 0.0

    @property
    def passing(self) -> bool:
        """Whether the robot is inside a door-like opening now (walls seen beyond its jambs)."""
        return self._passage is not None and self._passage.walls

    def reset(self) -> None:
        """Forget an opening being passed (e.g. after the odometry was reset)."""
        self._passage = None
        self._last = None
        self._last_pose = None

    def update(
        self, points: np.ndarray, pose: np.ndarray | tuple[float, float, float], stamp: float = 0.0
    ) -> Doorway | None:
        """Feed one scan's points; returns the doorway just passed through, if any.

        A robot that moved more than ``max_step`` since the previous scan (a sparse log: a
        scan every second or every few seconds) could step over an opening between two scans;
        the detector then also measures at poses in between (interpolated every
        ``max_step``), on the same points seen from there: the local map holds the jambs.

        Args:
            points: ``(k, 2)`` obstacle points in the robot frame (x forward, y left), metres.
            pose: the robot's ``(x, y, theta)`` in the odometry frame.
            stamp: seconds, the scan's time (reported in the :class:`Doorway`).
        """
        p = np.asarray(pose, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"pose must be a finite (x, y, theta) triple, got {pose!r}")
        pts = np.asarray(points, dtype=np.float64)
        prev = self._last_pose
        result = None
        if prev is not None:
            n = math.ceil(float(np.hypot(*(p[:2] - prev[:2]))) / self.params.max_step)
            if n > 1:
                c, s = math.cos(p[2]), math.sin(p[2])
                world = p[:2] + pts @ np.array([[c, s], [-s, c]])
                dth = math.atan2(math.sin(p[2] - prev[2]), math.cos(p[2] - prev[2]))
                for k in range(1, n):
                    f = k / n
                    q = np.array([*(prev[:2] + f * (p[:2] - prev[:2])), prev[2] + f * dth])
                    t = self._last_stamp + f * (stamp - self._last_stamp)
                    result = self._step(to_robot_frame(world, q), q, t) or result
        return self._step(pts, p, stamp) or result

    @staticmethod
    def _crossed(pas: _Passage, position: np.ndarray) -> bool:
        """Whether the robot went from one side of the opening to the other: across the line
        through its narrowest measurement, or through its first (an opening as deep as a
        table, whose narrowest pair of jambs moves along it as the robot goes through, may be
        left before the robot passes the last narrowest line)."""
        for centre in (pas.center, pas.anchor):
            if centre is None:
                continue
            before = float((pas.entry - centre) @ pas.normal)
            after = float((position - centre) @ pas.normal)
            if before * after < 0.0:
                return True
        return False

    def _step(self, points: np.ndarray, p: np.ndarray, stamp: float) -> Doorway | None:
        """One measurement at the robot's pose ``p`` (see :meth:`update`)."""
        prm = self.params
        pas = self._passage
        step = 0.0 if self._last is None else float(np.hypot(*(p[:2] - self._last)))
        self._last = p[:2].copy()
        self._last_pose = p.copy()
        self._last_stamp = stamp
        limit = prm.max_width + (prm.hysteresis if pas is not None else 0.0)
        m = _measure(points, prm, limit)
        here = None
        if m is not None:
            c, s = math.cos(p[2]), math.sin(p[2])
            normal = np.array([c * m.normal[0] - s * m.normal[1], s * m.normal[0] + c * m.normal[1]])
            here = _Passage(p[:2].copy(), _to_world(p, m.center), normal, m.width, stamp, m.walls)
        if pas is not None and here is not None and pas.same(here, prm.same_opening):
            # still in the same opening
            pas.travelled += step
            pas.walls = pas.walls or here.walls
            if here.width < pas.width:
                pas.center, pas.normal, pas.width, pas.stamp = (
                    here.center,
                    here.normal,
                    here.width,
                    here.stamp,
                )
            return None
        result = None
        if pas is not None:
            # leaving the opening (or meeting another one): report it if it was passed through
            pas.travelled += step
            if pas.walls and pas.travelled <= prm.max_depth and self._crossed(pas, p[:2]):
                after = float((p[:2] - pas.center) @ pas.normal)
                direction = pas.normal if after > 0.0 else -pas.normal
                result = Doorway(
                    center=(float(pas.center[0]), float(pas.center[1])),
                    width=pas.width,
                    orientation=math.atan2(direction[1], direction[0]),
                    stamp=pas.stamp,
                )
        # a narrow measurement starts a passage (a door once walls are seen beyond its jambs)
        if here is not None:
            here.anchor = here.center.copy()
        self._passage = here
        return result
