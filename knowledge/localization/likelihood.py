"""Likelihood fields: how far each cell of an occupancy grid is from the nearest obstacle.

A laser endpoint that falls ``d`` metres from the nearest occupied cell is explained by the
map with a likelihood that falls off as ``exp(−d²/2σ²)`` (Thrun, Burgard, Fox,
*Probabilistic Robotics*, Sect. 6.4, the "likelihood field" model). :class:`LikelihoodField`
keeps the distances of one grid; the scan matcher (:mod:`~knowledge.localization.scan_matching`)
and the particle filter (:mod:`~knowledge.localization.mcl`) turn them into scores with the
``σ`` they need.

Layout: arrays here are in **map orientation** — row 0 at the *bottom* (``y`` grows with the
row), column 0 at the left — so that cell ``(iy, ix)`` holds the world points with
``ix = floor((x − ox) / res)``, ``iy = floor((y − oy) / res)``, ``(ox, oy)`` the grid's
origin (its lower-left corner). An :class:`~knowledge.metric.grid.OccupancyGrid` stores
image orientation (row 0 at the top) and may be rotated (``origin`` yaw): poses are moved
into the map frame with :meth:`LikelihoodField.to_map` before they are looked up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np
import numpy.typing as npt

from knowledge.localization.se2 import compose, inverse
from knowledge.metric.grid import OccupancyGrid

__all__ = ["LikelihoodField", "distance_field", "surface"]


@numba.njit(cache=True, nogil=True)
def _gauss(d: np.ndarray, k: float) -> np.ndarray:
    out = np.empty(d.shape, dtype=np.float32)
    for i in range(d.shape[0]):
        for j in range(d.shape[1]):
            v = d[i, j]
            out[i, j] = math.exp(k * v * v)
    return out


def surface(occupied: np.ndarray) -> np.ndarray:
    """The occupied cells that are not inside an obstacle (not all of their 8 neighbours are
    occupied): where a laser beam can end. The inside of a thick wall or a solid block is
    not; a map built from scans has only such cells anyway."""
    occ = np.asarray(occupied, dtype=bool)
    inner = cv2.erode(occ.astype(np.uint8), np.ones((3, 3), np.uint8), borderValue=1).astype(bool)
    return occ & ~inner


def distance_field(occupied: np.ndarray, resolution: float, max_distance: float) -> np.ndarray:
    """``(rows, cols)`` float32 metres from each cell's centre to the nearest occupied cell,
    clipped at ``max_distance`` (and ``max_distance`` everywhere when nothing is occupied).

    Distances are between cell centres: an endpoint on an obstacle cell's near face (where a
    ray cast stops) is half a cell from it. Exact Euclidean distances (OpenCV's precise
    distance transform)."""
    occ = np.asarray(occupied, dtype=bool)
    if not occ.any():
        return np.full(occ.shape, max_distance, dtype=np.float32)
    src = np.where(occ, 0, 255).astype(np.uint8)
    d = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.minimum(d * np.float32(resolution), np.float32(max_distance)).astype(np.float32)


@dataclass(frozen=True, eq=False)
class LikelihoodField:
    """Distances to the nearest obstacle of a grid, in map orientation (see the module docstring).

    Attributes:
        distance: ``(rows, cols)`` float32 metres, clipped at ``max_distance``.
        free: ``(rows, cols)`` bool, cells known to be free.
        occupied: ``(rows, cols)`` bool.
        resolution: metres per cell.
        origin: world ``(x, y, yaw)`` of the lower-left corner (the grid's ``origin``).
        max_distance: the clipping distance, metres.
    """

    distance: np.ndarray
    free: np.ndarray
    occupied: np.ndarray
    resolution: float
    origin: tuple[float, float, float]
    max_distance: float

    @classmethod
    def from_grid(cls, grid: OccupancyGrid, max_distance: float = 2.0) -> LikelihoodField:
        """The field of an occupancy grid: distances to the occupied cells beside free ones
        (:func:`surface`), so that an endpoint inside a solid block scores low."""
        if not (math.isfinite(max_distance) and max_distance > 0):
            raise ValueError(f"max_distance must be a positive number of metres, got {max_distance}")
        occ = np.ascontiguousarray(grid.occupied[::-1])
        free = np.ascontiguousarray(grid.free[::-1])
        return cls(
            distance_field(surface(occ), grid.resolution, max_distance),
            free,
            occ,
            float(grid.resolution),
            tuple(float(v) for v in grid.origin),  # type: ignore[arg-type]
            float(max_distance),
        )

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.distance.shape[0]), int(self.distance.shape[1]))

    def score(self, sigma: float) -> np.ndarray:
        """``(rows, cols)`` float32 ``exp(−d²/2σ²)``: 1 on obstacles, falling off around them."""
        if not sigma > 0:
            raise ValueError(f"sigma must be a positive number of metres, got {sigma}")
        return _gauss(self.distance, -0.5 / (sigma * sigma))

    def to_map(self, poses: npt.ArrayLike) -> np.ndarray:
        """World poses ``(..., 3)`` in the frame of the field's lower-left corner (no yaw)."""
        p = np.asarray(poses, dtype=np.float64)
        if self.origin[2] == 0.0:
            return np.concatenate(
                [p[..., :1] - self.origin[0], p[..., 1:2] - self.origin[1], p[..., 2:3]], axis=-1
            )
        return compose(inverse(np.asarray(self.origin)), p)

    def to_world(self, poses: npt.ArrayLike) -> np.ndarray:
        """The inverse of :meth:`to_map`."""
        return compose(np.asarray(self.origin), np.asarray(poses, dtype=np.float64))

    def free_positions(self) -> np.ndarray:
        """``(N, 2)`` map-frame ``(x, y)`` centres of the free cells."""
        iy, ix = np.nonzero(self.free)
        return np.stack([(ix + 0.5) * self.resolution, (iy + 0.5) * self.resolution], axis=-1)
