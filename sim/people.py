"""Simulated people: two legs with a walking gait, following paths through a world.

A :class:`SimPerson` walks along a polyline of waypoints at a constant speed (m/s). What a
laser at ``scan_height`` above the floor sees of each leg is a circle (radius ``leg_radius``)
where the leg — the straight line from the hip (at ``hip_height``, moving with the body) to
the foot — crosses the scan plane.

The gait, per leg, is a cycle over one stride ``S = 2·step_length`` of walked distance:

* stance (the first ``stance_fraction`` β of the cycle): the foot stays planted on the floor
  while the body moves on, so its offset from the body along the walking direction falls
  linearly from ``+a`` to ``−a`` with ``a = β·S/2``;
* swing (the rest): the foot swings forward, its offset going back from ``−a`` to ``+a`` on a
  half-cosine.

The two legs are half a cycle apart (with β > ½ both feet are down at the heel strikes), and
they stand ``stance_width`` apart across the walking direction. Because the phase follows the
walked distance, a faster walker takes the same steps more often. At the scan height the
leg's offset is the foot's scaled by ``1 − scan_height/hip_height``.

At the end of its path a person turns around (``mode="pingpong"``), walks back to the first
waypoint (``"loop"``) or stops and stands with its legs together (``"stop"``). A person with
``speed = 0`` stands at the first waypoint facing the second (or +x).

:meth:`SimPerson.legs` gives two :class:`~sim.lms_world.Leg` whose centres are
functions of time — exactly what :class:`~sim.lms_world.LmsWorld` takes::

    world = LmsWorld(grid, pose, legs=legs_of(people))
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from knowledge.metric.grid import OccupancyGrid
from sim.lms_world import LEG_RADIUS, Leg

Point = tuple[float, float]
MODES = ("pingpong", "loop", "stop")

_CLEARANCE: weakref.WeakKeyDictionary[OccupancyGrid, np.ndarray] = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class Gait:
    """How a person walks (metres; see the module doc)."""

    step_length: float = 0.6
    stance_fraction: float = 0.6
    stance_width: float = 0.2
    scan_height: float = 0.3
    hip_height: float = 0.9
    leg_radius: float = LEG_RADIUS

    def __post_init__(self) -> None:
        for name in ("step_length", "stance_width", "hip_height", "leg_radius"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"Gait.{name} must be a positive number of metres, got {v!r}")
        if not 0.0 < self.stance_fraction < 1.0:
            raise ValueError(f"Gait.stance_fraction must be in (0, 1), got {self.stance_fraction!r}")
        if not 0.0 <= self.scan_height < self.hip_height:
            raise ValueError(
                f"Gait.scan_height must be in [0, hip_height={self.hip_height}) metres, got {self.scan_height!r}"
            )

    @property
    def stride(self) -> float:
        """Walked distance per gait cycle, metres."""
        return 2.0 * self.step_length

    def foot_offset(self, phase: float) -> float:
        """The foot's offset from the body along the walking direction at cycle ``phase`` ∈ [0, 1)."""
        beta = self.stance_fraction
        a = beta * self.stride / 2.0
        if phase < beta:
            return a - 2.0 * a * phase / beta
        u = (phase - beta) / (1.0 - beta)
        return -a + a * (1.0 - math.cos(math.pi * u))

    def in_stance(self, phase: float) -> bool:
        return phase < self.stance_fraction


class SimPerson:
    """A person walking along ``waypoints`` (world metres) at ``speed`` m/s (see the module doc).

    Args:
        waypoints: ``(K, 2)`` path, K ≥ 1 (K = 1 only for a standing person).
        speed: m/s (0 = standing).
        mode: ``"pingpong"``, ``"loop"`` or ``"stop"`` at the end of the path.
        gait: the gait parameters.
        start_time: seconds; before it the person stands at the start.
        phase: initial gait phase of the first leg, in cycles [0, 1).
    """

    def __init__(
        self,
        waypoints: Sequence[Point] | np.ndarray,
        speed: float = 1.0,
        *,
        mode: str = "pingpong",
        gait: Gait | None = None,
        start_time: float = 0.0,
        phase: float = 0.0,
    ) -> None:
        W = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        if W.shape[0] == 0 or not np.isfinite(W).all():
            raise ValueError("a person needs at least one finite (x, y) waypoint in metres")
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed must be >= 0 m/s, got {speed!r}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if mode == "loop" and W.shape[0] >= 2:
            W = np.vstack([W, W[:1]])
        seg = np.hypot(*np.diff(W, axis=0).T) if W.shape[0] > 1 else np.zeros(0)
        keep = np.concatenate([[True], seg > 1e-9]) if seg.size else np.array([True])
        W = W[keep]
        if speed > 0 and W.shape[0] < 2:
            raise ValueError("a walking person needs at least two distinct waypoints")
        self.waypoints = W
        self.speed = float(speed)
        self.mode = mode
        self.gait = gait or Gait()
        self.start_time = float(start_time)
        self.phase = float(phase) % 1.0
        self._cum = (
            np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(W, axis=0).T))])
            if W.shape[0] > 1
            else np.zeros(1)
        )

    @property
    def length(self) -> float:
        """Length of the path in metres."""
        return float(self._cum[-1])

    def distance(self, t: float) -> float:
        """Metres walked by time ``t`` (seconds)."""
        return self.speed * max(0.0, t - self.start_time)

    def _arc(self, t: float) -> tuple[float, float]:
        """Arc length along the path and direction (+1 forward, −1 back) at time ``t``."""
        d = self.distance(t)
        L = self.length
        if L <= 0:
            return 0.0, 1.0
        if self.mode == "loop":
            return d % L, 1.0
        if self.mode == "stop":
            return min(d, L), 1.0
        s = d % (2 * L)
        return (s, 1.0) if s <= L else (2 * L - s, -1.0)

    def walking(self, t: float) -> bool:
        """False while standing (before the start, at the end with mode "stop", speed 0)."""
        return (
            self.speed > 0
            and t >= self.start_time
            and not (self.mode == "stop" and self.distance(t) >= self.length)
        )

    def body(self, t: float) -> tuple[float, float, float]:
        """Body (hip centre) pose ``(x, y, heading)`` at time ``t``: metres, radians."""
        W = self.waypoints
        if W.shape[0] == 1:
            return float(W[0, 0]), float(W[0, 1]), 0.0
        s, direction = self._arc(t)
        i = int(np.clip(np.searchsorted(self._cum, s, side="right") - 1, 0, W.shape[0] - 2))
        seg_len = self._cum[i + 1] - self._cum[i]
        u = (W[i + 1] - W[i]) / seg_len
        p = W[i] + u * (s - self._cum[i])
        heading = math.atan2(u[1] * direction, u[0] * direction)
        return float(p[0]), float(p[1]), heading

    def position(self, t: float) -> Point:
        x, y, _ = self.body(t)
        return (x, y)

    def velocity(self, t: float) -> Point:
        """Body velocity ``(vx, vy)`` in m/s at time ``t``."""
        if not self.walking(t):
            return (0.0, 0.0)
        _, _, h = self.body(t)
        return (self.speed * math.cos(h), self.speed * math.sin(h))

    def leg_phases(self, t: float) -> tuple[float, float]:
        """Gait phases of the two legs in cycles [0, 1) (half a cycle apart)."""
        c = self.distance(t) / self.gait.stride + self.phase
        return (c % 1.0, (c + 0.5) % 1.0)

    def leg_positions(self, t: float) -> np.ndarray:
        """``(2, 2)`` world centres (metres) of the two leg circles in the scan plane at time ``t``."""
        x, y, h = self.body(t)
        ux, uy = math.cos(h), math.sin(h)
        nx, ny = -uy, ux
        g = self.gait
        scale = 1.0 - g.scan_height / g.hip_height
        out = np.empty((2, 2))
        phases = self.leg_phases(t)
        for k, side in enumerate((1.0, -1.0)):
            along = scale * g.foot_offset(phases[k]) if self.walking(t) else 0.0
            out[k, 0] = x + side * g.stance_width / 2 * nx + along * ux
            out[k, 1] = y + side * g.stance_width / 2 * ny + along * uy
        return out

    def legs(self) -> tuple[Leg, Leg]:
        """The two legs as moving circles for :class:`~sim.lms_world.LmsWorld`."""

        def leg(k: int) -> Leg:
            def pos(t: float) -> Point:
                p = self.leg_positions(t)[k]
                return (float(p[0]), float(p[1]))

            return Leg(pos, self.gait.leg_radius)

        return leg(0), leg(1)


def legs_of(people: Iterable[SimPerson]) -> list[Leg]:
    """All legs of ``people``, for ``LmsWorld(grid, pose, legs=...)``."""
    out: list[Leg] = []
    for p in people:
        out.extend(p.legs())
    return out


def clear_path(grid: OccupancyGrid, a: Point, b: Point, clearance: float = 0.3) -> bool:
    """True if the straight path ``a → b`` keeps ``clearance`` metres from every non-free cell."""
    dist = _clearance_map(grid)
    n = max(2, int(math.hypot(b[0] - a[0], b[1] - a[1]) / (grid.resolution / 2)) + 1)
    pts = np.linspace(a, b, n)
    cells = grid.world_to_cell(pts)
    inside = grid.in_bounds(cells)
    if not inside.all():
        return False
    return bool((dist[cells[:, 0], cells[:, 1]] >= clearance).all())


def _clearance_map(grid: OccupancyGrid) -> np.ndarray:
    """``(rows, cols)`` metres from each cell to the nearest non-free cell (cached per grid)."""
    cached = _CLEARANCE.get(grid)
    if cached is None:
        cached = cv2.distanceTransform(grid.free.astype(np.uint8), cv2.DIST_L2, 5) * grid.resolution
        _CLEARANCE[grid] = cached
    return cached


def walkers_in(
    grid: OccupancyGrid,
    centre: Point,
    n: int,
    *,
    seed: int = 0,
    reach: float = 4.0,
    speed: tuple[float, float] = (0.6, 1.4),
    waypoints: int = 3,
    clearance: float = 0.3,
) -> list[SimPerson]:
    """``n`` people walking back and forth along random collision-free paths near ``centre``.

    Each path has up to ``waypoints`` points, all free cells with ``clearance`` metres to any
    obstacle, between 0.8 m and ``reach`` metres from ``centre``, joined by straight clear
    lines; speeds are uniform in ``speed`` (m/s). Fewer people come back if the space is tight.
    """
    if n <= 0:
        return []
    rng = np.random.default_rng(seed)
    dist = _clearance_map(grid)
    cells = np.argwhere(dist >= clearance)
    if cells.size == 0:
        return []
    xy = grid.cell_to_world(cells)
    r = np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1])
    cand = xy[(r >= 0.8) & (r <= reach)]
    if len(cand) < 2:
        return []
    people: list[SimPerson] = []
    for _ in range(n):
        for _attempt in range(50):
            path = [cand[rng.integers(len(cand))]]
            for _k in range(waypoints - 1):
                for _try in range(30):
                    q = cand[rng.integers(len(cand))]
                    if math.dist(path[-1], q) >= 1.0 and clear_path(
                        grid, tuple(path[-1]), tuple(q), clearance
                    ):
                        path.append(q)
                        break
            if len(path) >= 2:
                people.append(
                    SimPerson(
                        np.array(path),
                        float(rng.uniform(*speed)),
                        mode="pingpong",
                        phase=float(rng.uniform(0, 1)),
                    )
                )
                break
    return people
