"""What the virtual LMS sees: an occupancy grid, a sensor pose, and people's legs.

Ranges come from the grid ray caster (:func:`knowledge.metric.raycast.cast`, or any
function with its signature) combined with an exact ray–circle intersection for the legs —
circles of about 6 cm radius whose centres are functions of time — taking the nearer hit.
Gaussian noise is added to beams that hit something; beams that hit nothing within
``max_range`` return ``max_range``.

Times are seconds of simulation time (the virtual LMS passes seconds since it started).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from knowledge.errors import MapError
from knowledge.metric.beams import beam_angles
from knowledge.metric.grid import OccupancyGrid

Pose = tuple[float, float, float]
Point = tuple[float, float]

#: Leg radius in metres (an adult's calf, as seen by a laser at knee height).
LEG_RADIUS = 0.06


class Caster(Protocol):
    """The signature of :func:`knowledge.metric.raycast.cast`."""

    def __call__(
        self,
        grid: OccupancyGrid,
        poses: np.ndarray,
        *,
        n_beams: int,
        max_range: float,
        fov: float,
        angle_min: float | None,
        noise_std: float,
        rng: np.random.Generator | None,
        unknown_blocks: bool,
    ) -> np.ndarray: ...


def default_caster() -> Caster:
    """The project's fast ray caster (imported on first use)."""
    from knowledge.metric.raycast import cast

    return cast


@dataclass(frozen=True)
class Leg:
    """A vertical cylinder cut by the scan plane: a circle moving in the world frame.

    Attributes:
        position: world ``(x, y)`` of the centre in metres, or a function of time giving it.
        radius: metres.
    """

    position: Point | Callable[[float], Point]
    radius: float = LEG_RADIUS

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"a leg's radius must be a positive number of metres, got {self.radius}")

    def at(self, t: float) -> Point:
        p = self.position(t) if callable(self.position) else self.position
        return (float(p[0]), float(p[1]))


def walking_person(
    start: Point, end: Point, *, speed: float = 1.0, phase: float = 0.0, stance: float = 0.2
) -> tuple[Leg, Leg]:
    """Two legs of a person walking back and forth between ``start`` and ``end``.

    The body moves at ``speed`` m/s along the segment (turning at its ends); the legs stand
    ``stance`` metres apart across the walking direction and swing ±10 cm along it.
    """
    sx, sy = start
    ex, ey = end
    length = math.hypot(ex - sx, ey - sy)
    if length <= 0 or speed <= 0:
        raise ValueError("a walking person needs distinct start and end points and a positive speed (m/s)")
    ux, uy = (ex - sx) / length, (ey - sy) / length
    nx, ny = -uy, ux

    def body(t: float) -> tuple[float, float, float]:
        s = (speed * t + phase) % (2 * length)
        d = s if s <= length else 2 * length - s
        direction = 1.0 if s <= length else -1.0
        return sx + d * ux, sy + d * uy, direction

    def leg(side: float) -> Callable[[float], Point]:
        def pos(t: float) -> Point:
            bx, by, direction = body(t)
            swing = 0.1 * math.sin(2 * math.pi * 0.9 * t) * side * direction
            return (bx + side * stance / 2 * nx + swing * ux, by + side * stance / 2 * ny + swing * uy)

        return pos

    return Leg(leg(1.0)), Leg(leg(-1.0))


def ray_circle_ranges(
    origin: Point, angles: np.ndarray, centres: np.ndarray, radii: np.ndarray
) -> np.ndarray:
    """Distance along each ray to the nearest circle, ``inf`` where none is hit.

    Args:
        origin: ray origin ``(x, y)`` in metres.
        angles: ``(B,)`` world ray directions in radians.
        centres: ``(K, 2)`` circle centres; radii: ``(K,)`` radii (metres).

    Returns:
        ``(B,)`` float64 metres; 0 for rays starting inside a circle.
    """
    a = np.asarray(angles, dtype=np.float64)
    if len(centres) == 0:
        return np.full(a.shape, np.inf)
    d = np.stack([np.cos(a), np.sin(a)], axis=-1)  # (B, 2)
    oc = np.asarray(centres, dtype=np.float64) - np.asarray(origin, dtype=np.float64)  # (K, 2)
    b = d @ oc.T  # (B, K): projection of the centre on the ray
    c = (oc**2).sum(axis=1) - np.asarray(radii, dtype=np.float64) ** 2  # (K,)
    disc = b**2 - c[None, :]
    with np.errstate(invalid="ignore"):
        root = np.sqrt(disc)
    near = b - root
    far = b + root
    s = np.where(near >= 0, near, np.where(far >= 0, 0.0, np.inf))  # inside a circle: 0
    s = np.where(disc >= 0, s, np.inf)
    return np.asarray(s.min(axis=1))


class LmsWorld:
    """A static map, a sensor pose and moving legs, producing laser ranges.

    Args:
        grid: the walls.
        pose: the sensor's world pose ``(x, y, heading)`` (metres, radians) or a function of
            time giving it; None puts it on the free cell nearest the map centre that has at
            least 0.3 m clearance, heading 0.
        legs: the moving circles.
        noise_std: standard deviation of the range noise in metres (hits only).
        seed: seed of the noise generator.
        caster: the grid ray caster (default :func:`knowledge.metric.raycast.cast`).
        unknown_blocks: unknown cells stop rays, as unexplored space does for a real map.
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        pose: Pose | Callable[[float], Pose] | None = None,
        legs: Sequence[Leg] = (),
        *,
        noise_std: float = 0.01,
        seed: int | None = 0,
        caster: Caster | None = None,
        unknown_blocks: bool = True,
    ) -> None:
        if not (math.isfinite(noise_std) and noise_std >= 0):
            raise ValueError(f"noise_std must be >= 0 metres, got {noise_std}")
        self.grid = grid
        self.pose = default_sensor_pose(grid) if pose is None else pose
        self.legs = tuple(legs)
        self.noise_std = noise_std
        self.unknown_blocks = unknown_blocks
        self._rng = np.random.default_rng(seed)
        self._caster = caster if caster is not None else default_caster()

    def sensor_pose(self, t: float) -> np.ndarray:
        """``(3,)`` float64 world pose of the sensor at time ``t``."""
        p = self.pose(t) if callable(self.pose) else self.pose
        return np.array([float(p[0]), float(p[1]), float(p[2])])

    def ranges(
        self, t: float, *, n_beams: int, fov: float, max_range: float, angle_min: float | None = None
    ) -> np.ndarray:
        """``(n_beams,)`` float32 ranges in metres at time ``t``; ``max_range`` where nothing is hit.

        Beams point where :func:`knowledge.metric.beams.beam_angles` lays them out, relative to
        the sensor heading: ``[angle_min, angle_min + fov]`` inclusive with ``angle_min``
        defaulting to ``-fov/2``, or for a full circle (``fov`` = 2π) ``angle_min + i·2π/n``
        with ``angle_min`` defaulting to 0.
        """
        pose = self.sensor_pose(t)
        grid_r = np.asarray(
            self._caster(
                self.grid,
                pose,
                n_beams=n_beams,
                max_range=max_range,
                fov=fov,
                angle_min=angle_min,
                noise_std=0.0,
                rng=None,
                unknown_blocks=self.unknown_blocks,
            ),
            dtype=np.float64,
        ).reshape(-1)
        rel = beam_angles(n_beams, fov, angle_min)  # the caster's layout: legs and walls agree
        r = grid_r
        if self.legs:
            centres = np.array([leg.at(t) for leg in self.legs])
            radii = np.array([leg.radius for leg in self.legs])
            r = np.minimum(r, ray_circle_ranges((pose[0], pose[1]), pose[2] + rel, centres, radii))
        hit = r < max_range
        if self.noise_std > 0:
            r = np.where(hit, r + self._rng.normal(0.0, self.noise_std, r.shape), r)
        r = np.clip(r, 0.0, max_range)
        return r.astype(np.float32)


def default_sensor_pose(grid: OccupancyGrid, clearance: float = 0.3) -> Pose:
    """A free cell near the map centre with at least ``clearance`` metres to any non-free cell.

    Falls back to the free cell with the largest clearance when none has enough; raises
    MapError for a map without free cells.
    """
    free = grid.free.astype(np.uint8)
    if not free.any():
        raise MapError(f"{grid.name}: the map has no free cell to put the sensor on")
    dist = cv2.distanceTransform(free, cv2.DIST_L2, 5) * grid.resolution
    ok = dist >= clearance
    if not ok.any():
        ok = dist >= dist.max()
    cells = np.argwhere(ok)
    centre = np.array(grid.shape, dtype=np.float64) / 2.0
    best = cells[np.argmin(((cells + 0.5 - centre) ** 2).sum(axis=1))]
    x, y = grid.cell_to_world(best)
    return (float(x), float(y), 0.0)


def load_world_grid(spec: str | None, resolution: float | None = None) -> OccupancyGrid:
    """The grid named by a ``--world`` argument (:func:`sim.world.load_world`: the same
    syntax as every simulator command)."""
    from sim.world import load_world

    return load_world(spec, resolution)[0]


def people_in(grid: OccupancyGrid, centre: Point, n: int, *, seed: int = 0, reach: float = 4.0) -> list[Leg]:
    """Legs of ``n`` people walking between random free spots within ``reach`` metres of ``centre``."""
    if n <= 0:
        return []
    rng = np.random.default_rng(seed)
    free = grid.free.astype(np.uint8)
    dist = cv2.distanceTransform(free, cv2.DIST_L2, 5) * grid.resolution
    cells = np.argwhere(dist >= 0.3)
    if cells.size == 0:
        return []
    xy = grid.cell_to_world(cells)
    near = xy[np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) <= reach]
    near = near[np.hypot(near[:, 0] - centre[0], near[:, 1] - centre[1]) >= 0.8]
    if len(near) < 2:
        return []
    legs: list[Leg] = []
    for _ in range(n):
        a, b = near[rng.choice(len(near), size=2, replace=False)]
        if math.hypot(*(b - a)) < 0.5:
            continue
        legs.extend(
            walking_person(
                (float(a[0]), float(a[1])),
                (float(b[0]), float(b[1])),
                speed=float(rng.uniform(0.6, 1.4)),
                phase=float(rng.uniform(0, 5)),
            )
        )
    return legs
