"""A small asymmetric test world for the localization tests: a map, a path through it, the
scans a 180° laser sees along it and drifting odometry."""

from __future__ import annotations

import itertools
import math

import numpy as np

from knowledge.localization.se2 import between, compose
from knowledge.metric.beams import beam_angles
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast

RES = 0.05
ANGLES = beam_angles(181, math.pi)
RANGE_MAX = 20.0


def world() -> OccupancyGrid:
    """14 × 9 m: a corridor along the bottom, three rooms of different sizes above it with
    doors, boxes here and there (no two places look alike)."""
    h, w = int(9 / RES), int(14 / RES)
    occ = np.zeros((h, w), dtype=bool)  # map orientation first (row = y), flipped at the end

    def box(x0: float, y0: float, x1: float, y1: float) -> None:
        occ[int(y0 / RES) : int(y1 / RES), int(x0 / RES) : int(x1 / RES)] = True

    t = 0.1
    box(0, 0, 14, t), box(0, 9 - t, 14, 9), box(0, 0, t, 9), box(14 - t, 0, 14, 9)  # outer walls
    box(0, 3, 14, 3 + t)  # corridor wall
    for x0, x1 in ((1.0, 2.0), (6.5, 7.3), (10.5, 11.5)):  # doors
        occ[int(3 / RES) : int((3 + t) / RES) + 1, int(x0 / RES) : int(x1 / RES)] = False
    box(5, 3, 5 + t, 9), box(9, 3, 9 + t, 9)  # room walls
    box(2.5, 6.5, 3.5, 7.0), box(7.5, 7.5, 8.5, 8.9), box(12.0, 4.0, 12.6, 4.6), box(4.0, 1.0, 4.4, 1.4)
    box(12.5, 0.1, 13.9, 0.8)
    return OccupancyGrid.from_masks(occ[::-1], RES, name="test-world")


def labels(grid: OccupancyGrid) -> np.ndarray:
    """Label codes in image orientation: 2 corridor below y = 3 m, 1 room above, 0 off free cells."""
    rows, _ = grid.shape
    yy = (rows - np.arange(rows) - 0.5) * RES
    lab = np.where(yy[:, None] < 3.0, 2, 1) * np.ones(grid.shape, dtype=np.uint8)
    return np.where(grid.free, lab, 0).astype(np.uint8)


def path(step: float = 0.1) -> np.ndarray:
    """``(N, 3)`` true laser poses: along the corridor, into the middle room and back out."""
    way = [(0.8, 1.5), (6.9, 1.5), (6.9, 5.0), (7.5, 6.0), (6.9, 5.0), (6.9, 1.5), (12.0, 1.8), (13.0, 2.2)]
    out = []
    for (x0, y0), (x1, y1) in itertools.pairwise(way):
        n = max(1, int(math.hypot(x1 - x0, y1 - y0) / step))
        th = math.atan2(y1 - y0, x1 - x0)
        for k in range(n):
            out.append((x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n, th))
    return np.array(out)


def scans(grid: OccupancyGrid, poses: np.ndarray, seed: int = 0) -> np.ndarray:
    return cast(
        grid,
        poses,
        n_beams=181,
        fov=math.pi,
        max_range=RANGE_MAX,
        noise_std=0.01,
        rng=np.random.default_rng(seed),
    )


def drifting_odometry(
    poses: np.ndarray, seed: int = 0, drift: float = 0.02, scale: float = 1.03, *, from_truth: bool = False
) -> np.ndarray:
    """Odometry that overestimates distance by ``scale`` and drifts ``drift`` rad per metre,
    from the origin (or, ``from_truth``, from the first true pose)."""
    rng = np.random.default_rng(seed)
    odo = [np.array(poses[0], dtype=float) if from_truth else np.array([0.0, 0.0, 0.0])]
    for a, b in itertools.pairwise(poses):
        d = between(a, b)
        dist = math.hypot(d[0], d[1])
        noisy = np.array([d[0] * scale, d[1] * scale, d[2] + drift * dist + rng.normal(0, 0.002)])
        odo.append(compose(odo[-1], noisy))
    return np.array(odo)
