"""A ring of corridors around a block of rooms, for the loop-closure tests: a map, a path that
drives round it more than once, the scans a 180° laser sees along it and drifting odometry."""

from __future__ import annotations

import itertools
import math

import numpy as np

from knowledge.localization.scan_matching import scan_points
from knowledge.metric.beams import beam_angles
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast import cast
from support.localization_world import drifting_odometry as _drifting

RES = 0.05
BEAMS = 181
ANGLES = beam_angles(BEAMS, math.pi)
RANGE_MAX = 20.0
#: The corridors' centre line, anticlockwise from the bottom left corner (metres).
RING = ((1.5, 1.5), (16.5, 1.5), (16.5, 10.5), (1.5, 10.5), (1.5, 1.5))


def world() -> OccupancyGrid:
    """18 × 12 m: corridors 3 m wide round a 12 × 6 m block; boxes, niches and pillars along
    the walls so that no two stretches of corridor look alike."""
    h, w = int(12 / RES), int(18 / RES)
    occ = np.zeros((h, w), dtype=bool)  # map orientation first (row = y), flipped at the end

    def box(x0: float, y0: float, x1: float, y1: float, value: bool = True) -> None:
        occ[int(y0 / RES) : int(y1 / RES), int(x0 / RES) : int(x1 / RES)] = value

    t = 0.1
    box(0, 0, 18, t), box(0, 12 - t, 18, 12), box(0, 0, t, 12), box(18 - t, 0, 18, 12)  # outer walls
    box(3, 3, 15, 9)  # the block
    # niches cut into the block, boxes and pillars against the outer walls
    box(5.0, 3.0, 6.2, 3.6, False), box(10.0, 8.5, 11.5, 9.0, False), box(14.4, 4.0, 15.0, 5.5, False)
    box(3.0, 6.5, 3.5, 8.0, False)
    box(2.0, 0.1, 2.6, 0.5), box(8.0, 0.1, 9.5, 0.4), box(12.5, 0.1, 12.9, 0.9)
    box(17.4, 3.0, 17.9, 3.5), box(17.6, 7.0, 17.9, 9.5)
    box(13.0, 11.5, 14.5, 11.9), box(6.0, 11.2, 6.4, 11.9), box(0.1, 8.0, 0.7, 8.6), box(0.1, 4.0, 0.4, 6.0)
    box(9.0, 10.9, 9.3, 11.2)  # a pillar off the wall
    return OccupancyGrid.from_masks(occ[::-1], RES, name="ring")


def path(laps: float = 1.3, step: float = 0.1) -> np.ndarray:
    """``(N, 3)`` true laser poses round the ring, ``laps`` times, turning at the corners."""
    legs = list(itertools.pairwise(RING))
    total = sum(math.hypot(x1 - x0, y1 - y0) for (x0, y0), (x1, y1) in legs)
    out = []
    s = 0.0
    while s < laps * total:
        u = s % total
        for (x0, y0), (x1, y1) in legs:
            n = math.hypot(x1 - x0, y1 - y0)
            if u <= n:
                th = math.atan2(y1 - y0, x1 - x0)
                out.append((x0 + (x1 - x0) * u / n, y0 + (y1 - y0) * u / n, th))
                break
            u -= n
        s += step
    return np.array(out)


def scans(grid: OccupancyGrid, poses: np.ndarray, seed: int = 0) -> np.ndarray:
    return cast(
        grid,
        poses,
        n_beams=BEAMS,
        fov=math.pi,
        max_range=RANGE_MAX,
        noise_std=0.01,
        rng=np.random.default_rng(seed),
    )


def points(ranges: np.ndarray) -> list[np.ndarray]:
    """Each scan's endpoints ``(M, 2)`` in the laser's frame."""
    return [scan_points(r, ANGLES, range_max=RANGE_MAX) for r in ranges]


def drifting_odometry(
    poses: np.ndarray, seed: int = 0, drift: float = 0.01, scale: float = 1.02
) -> np.ndarray:
    """Odometry from the first true pose that overestimates distance by ``scale`` and turns
    ``drift`` rad per metre too far left (:func:`support.localization_world.drifting_odometry`)."""
    return _drifting(poses, seed, drift, scale, from_truth=True)
