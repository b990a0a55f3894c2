"""A slow, plain ray caster that the fast ones are tested against.

Each ray walks the grid cell by cell with the Amanatides–Woo traversal (J. Amanatides and
A. Woo, *A Fast Voxel Traversal Algorithm for Ray Tracing*, Eurographics 1987): keep the
ray parameter at which the next vertical and the next horizontal grid line is crossed, step
across whichever comes first, test the cell entered. Python loops, one ray at a time:
use it on small maps only. The semantics are those of :mod:`knowledge.metric.raycast`.
"""

from __future__ import annotations

import math

import numpy as np

from knowledge.metric.beams import (
    CORNER_EPS,
    as_poses,
    beam_angles,
    blocking_mask,
    check_max_range,
    check_n_beams,
    map_frame_directions,
)
from knowledge.metric.grid import OccupancyGrid

#: Cells: a sensor on a grid line belongs to the cell this far along its ray.
START_NUDGE = 1e-9


def reference_cast(
    grid: OccupancyGrid,
    poses: np.ndarray,
    *,
    n_beams: int = 360,
    max_range: float = 30.0,
    fov: float = 2.0 * math.pi,
    angle_min: float | None = None,
    unknown_blocks: bool = True,
) -> np.ndarray:
    """Ranges in metres, ``(N, n_beams)`` float32 (``(n_beams,)`` for one ``(3,)`` pose).

    Same arguments and meaning as :func:`knowledge.metric.raycast.cast` without noise.
    """
    p, single = as_poses(poses)
    angles = beam_angles(check_n_beams(n_beams), fov, angle_min)
    max_t = check_max_range(max_range) / grid.resolution
    blocked = blocking_mask(grid, unknown_blocks)
    start = grid.world_to_cell_float(p[:, :2])  # (N, 2) continuous (row, col)
    psi = map_frame_directions(grid, p[:, 2], angles)
    out = np.empty(psi.shape, dtype=np.float32)
    for i in range(psi.shape[0]):
        v0, u0 = float(start[i, 0]), float(start[i, 1])
        for j in range(psi.shape[1]):
            # map frame: x right, y up; grid: column u right, row v down
            du, dv = math.cos(psi[i, j]), -math.sin(psi[i, j])
            t = _walk(blocked, v0, u0, dv, du, max_t)
            out[i, j] = min(t, max_t) * grid.resolution
    return out[0] if single else out


def _walk(blocked: np.ndarray, v0: float, u0: float, dv: float, du: float, max_t: float) -> float:
    """Ray parameter (cells) where the ray enters its first blocking cell; ``inf`` if none."""
    rows, cols = blocked.shape

    def hits(r: int, c: int) -> bool:
        return 0 <= r < rows and 0 <= c < cols and bool(blocked[r, c])

    t_in, t_out = _slab(v0, u0, dv, du, rows, cols)
    t_stop = min(max_t, t_out)
    if t_in > t_stop:
        return math.inf
    # a sensor exactly on a grid line is in the cell its ray enters; outside the map the
    # walk simply crosses empty cells until it reaches it
    r, c = math.floor(v0 + START_NUDGE * dv), math.floor(u0 + START_NUDGE * du)
    if hits(r, c):
        return 0.0
    step_c = 1 if du > 0 else -1
    step_r = 1 if dv > 0 else -1
    next_u = (c + 1 - u0) / du if du > 0 else (u0 - c) / -du if du < 0 else math.inf
    next_v = (r + 1 - v0) / dv if dv > 0 else (v0 - r) / -dv if dv < 0 else math.inf
    delta_u = 1.0 / abs(du) if du != 0 else math.inf
    delta_v = 1.0 / abs(dv) if dv != 0 else math.inf
    while True:
        if next_u <= next_v:
            t = next_u
            if t > t_stop:
                return math.inf
            c += step_c
            next_u += delta_u
            if t <= START_NUDGE:
                continue  # a line through the sensor itself: the start cell was tested above
            # crossed a vertical grid line at row coordinate v: near a corner both rows touch
            v = v0 + t * dv
            rn = round(v)
            if abs(v - rn) < CORNER_EPS:
                if hits(rn - 1, c) or hits(rn, c):
                    return t
            elif hits(r, c):
                return t
        else:
            t = next_v
            if t > t_stop:
                return math.inf
            r += step_r
            next_v += delta_v
            if t <= START_NUDGE:
                continue
            u = u0 + t * du
            cn = round(u)
            if abs(u - cn) < CORNER_EPS:
                if hits(r, cn - 1) or hits(r, cn):
                    return t
            elif hits(r, c):
                return t


def _slab(v0: float, u0: float, dv: float, du: float, rows: int, cols: int) -> tuple[float, float]:
    """Ray parameters where the ray enters and leaves the map grown by CORNER_EPS (``t_in > t_out``: never)."""
    e = CORNER_EPS
    t_in, t_out = -math.inf, math.inf
    for p0, d, hi in ((v0, dv, rows), (u0, du, cols)):
        if d == 0.0:
            if not -e <= p0 <= hi + e:
                return math.inf, -math.inf
            continue
        a, b = (-e - p0) / d, (hi + e - p0) / d
        t_in, t_out = max(t_in, min(a, b)), min(t_out, max(a, b))
    return t_in, t_out
