"""Ray casting from arbitrary poses: grid-line crossings in rounds, with empty-space jumps.

A ray enters a new cell only where it crosses a grid line, so its first hit is the earliest
crossing of a vertical or a horizontal line whose far side blocks (a crossing near a grid
corner also tests the cells beside it, see :data:`~knowledge.metric.beams.CORNER_EPS`).
All rays advance together, in rounds:

1. *jump*: a ray may skip ahead by its clearance, the distance from its cell to the
   nearest blocking cell less the two half-diagonals that separate points of the two
   cells (precomputed once per map with a Euclidean distance transform);
2. *test*: the crossings of the next :data:`CHUNK_CELLS` cells of ray length are all
   enumerated and looked up at once; the earliest blocking one is the hit.

Rays that hit something, leave the map or reach the maximum range drop out. Everything is
in *cell units*: continuous grid coordinates ``v`` (row, down) and ``u`` (column, right),
with cell ``(r, c)`` spanning ``[r, r+1) × [c, c+1)``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from knowledge.metric.beams import CORNER_EPS

#: Ray length, in cells, whose crossings are tested per round.
CHUNK_CELLS = 16
#: Slack (cells) when enumerating crossings at the ends of a round: a crossing seen twice is harmless.
EPS_T = 1e-9
#: Cells: a sensor on a grid line belongs to the cell this far along its ray.
START_NUDGE = 1e-9
#: What a jump keeps back from the nearest blocking cell: two half-diagonals and a little.
JUMP_MARGIN = math.sqrt(2.0) + 1e-6


def clearance(blocked: np.ndarray) -> np.ndarray:
    """``(rows + 2, cols + 2)`` float64: how far a ray may jump from each cell, padded like the mask.

    For a free cell, the distance between its centre and the nearest blocking cell's centre
    less :data:`JUMP_MARGIN` (no point of the cell is closer to any point of a blocking
    cell than that); 0 for blocking cells and the padding ring; inf on a map with nothing
    that blocks.
    """
    out = np.zeros((blocked.shape[0] + 2, blocked.shape[1] + 2))
    if not blocked.any():
        out[1:-1, 1:-1] = np.inf
        return out
    dist = ndimage.distance_transform_edt(~blocked)
    out[1:-1, 1:-1] = np.maximum(dist - JUMP_MARGIN, 0.0)
    return out


def cast_rays(
    blocked: np.ndarray,
    jump: np.ndarray,
    v0: np.ndarray,
    u0: np.ndarray,
    du: np.ndarray,
    dv: np.ndarray,
    max_t: float,
) -> np.ndarray:
    """Ray parameter (cells) to the first blocking cell along each ray, ``max_t`` for misses.

    Args:
        blocked: ``(rows + 2, cols + 2)`` bool blocking mask padded by one free cell.
        jump: :func:`clearance` of the unpadded mask.
        v0, u0: ``(R,)`` continuous start coordinates (row, column) in the unpadded grid.
        du, dv: ``(R,)`` unit direction (column, row components).
        max_t: maximum range in cells.
    """
    rows, cols = blocked.shape[0] - 2, blocked.shape[1] - 2
    width = blocked.shape[1]
    flat = blocked.ravel()
    jflat = jump.ravel()
    result = np.full(v0.shape, float(max_t))

    t_in, t_out = slab(v0, u0, dv, du, rows, cols)
    t_lo = np.maximum(t_in, 0.0)
    t_hi = np.minimum(t_out, max_t)

    # the sensor's own cell; a sensor exactly on a grid line is in the cell its ray enters
    r0 = np.floor(v0 + START_NUDGE * dv)
    c0 = np.floor(u0 + START_NUDGE * du)
    inside = (r0 >= 0) & (r0 < rows) & (c0 >= 0) & (c0 < cols)
    own = inside & flat.take(((r0 + 1) * width + (c0 + 1)).astype(np.int64), mode="clip")
    result[own] = 0.0
    todo = np.flatnonzero(~own & (t_lo <= t_hi))
    tc = t_lo[todo]
    m = np.arange(int(CHUNK_CELLS) + 3, dtype=np.float64)
    while todo.size:
        vv, uu, dvv, duu, th = v0[todo], u0[todo], dv[todo], du[todo], t_hi[todo]
        # jump ahead by the clearance of the cell the ray is in (0 outside the map)
        at = (vv + tc * dvv + 1.0).astype(np.int64) * width + (uu + tc * duu + 1.0).astype(np.int64)
        tc = np.minimum(tc + jflat.take(at, mode="clip"), th)
        te = np.minimum(tc + CHUNK_CELLS, th)
        hit_t = np.full(todo.shape, np.inf)
        for vertical in (True, False):
            # crossings of the lines p = k (k integer) with t in [tc, te]; q is the other coordinate
            p0, d, q0, e = (uu, duu, vv, dvv) if vertical else (vv, dvv, uu, duu)
            fwd = d >= 0.0
            # from a little before tc (a crossing seen twice is harmless); from the sensor, strictly ahead
            tmin = np.where(tc > START_NUDGE, tc - 2.0 * EPS_T, START_NUDGE)
            first = p0 + tmin * d
            k0 = np.where(fwd, np.ceil(first) - 1.0, np.floor(first) + 1.0)  # one early: rounding
            step = np.where(fwd, 1.0, -1.0)
            k = k0[:, None] + step[:, None] * m
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                t = (k - p0[:, None]) / d[:, None]
                valid = (t > tmin[:, None]) & (t <= (te + EPS_T)[:, None]) & (d != 0.0)[:, None]
                t = np.where(valid, t, np.inf)
                q = q0[:, None] + np.where(valid, t, tc[:, None]) * e[:, None]
            # padded index of the cell entered across line k, and of the cells beside a corner
            kp = (k + np.where(fwd, 1.0, 0.0)[:, None]).astype(np.int64)
            qa = (q + (1.0 - CORNER_EPS)).astype(np.int64)
            qb = (q + (1.0 + CORNER_EPS)).astype(np.int64)
            if vertical:
                ia, ib = qa * width + kp, qb * width + kp
            else:
                ia, ib = kp * width + qa, kp * width + qb
            blk = flat.take(ia, mode="clip") | flat.take(ib, mode="clip")
            hit_t = np.minimum(hit_t, np.where(blk, t, np.inf).min(axis=1))
        hit = np.isfinite(hit_t)
        result[todo[hit]] = np.minimum(hit_t[hit], max_t)
        more = ~hit & (te < th)
        todo, tc = todo[more], te[more]
    return result


def slab(
    v0: np.ndarray, u0: np.ndarray, dv: np.ndarray, du: np.ndarray, rows: int, cols: int
) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameters where each ray enters and leaves the map rectangle (``t_in > t_out``: never).

    The rectangle is grown by :data:`CORNER_EPS`: cells on the map's edge can be touched at
    their corners from just outside it.
    """
    t_in = np.full(v0.shape, -np.inf)
    t_out = np.full(v0.shape, np.inf)
    e = CORNER_EPS
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for p0, d, hi in ((v0, dv, rows), (u0, du, cols)):
            a, b = (-e - p0) / d, (hi + e - p0) / d
            lo, up = np.minimum(a, b), np.maximum(a, b)
            par = d == 0.0
            inside = (p0 >= -e) & (p0 <= hi + e)
            lo = np.where(par, np.where(inside, -np.inf, np.inf), lo)
            up = np.where(par, np.where(inside, np.inf, -np.inf), up)
            t_in, t_out = np.maximum(t_in, lo), np.minimum(t_out, up)
    return t_in, t_out
