"""Ray casting from arbitrary poses, compiled: one grid-line crossing at a time.

Each ray walks the grid with the Amanatides–Woo traversal (see
:mod:`knowledge.metric.raycast_reference`, whose walk this is, compiled with numba): keep
the ray parameter of the next vertical and the next horizontal grid line, step across the
nearer, test the cell entered; a crossing within :data:`~knowledge.metric.beams.CORNER_EPS`
of a grid corner tests both cells beside the corner. A ray costs one step per cell it
crosses (~1.4 per cell of range), ~3 ns a step.

Everything is in *cell units*: continuous grid coordinates ``v`` (row, down) and ``u``
(column, right), with cell ``(r, c)`` spanning ``[r, r+1) × [c, c+1)``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from knowledge.metric.beams import CORNER_EPS

#: Cells: a sensor on a grid line belongs to the cell this far along its ray.
START_NUDGE = 1e-9


@numba.njit(cache=True, nogil=True)
def cast_rays(blocked: np.ndarray, start: np.ndarray, psi: np.ndarray, max_t: float) -> np.ndarray:
    """``(N, B)`` float64 ray parameter (cells) to the first blocking cell, ``max_t`` for misses.

    Args:
        blocked: ``(rows, cols)`` bool blocking mask (image orientation).
        start: ``(N, 2)`` continuous start coordinates ``(v, u)`` (row, column) in cells.
        psi: ``(N, B)`` map-frame ray angles, radians counter-clockwise from +x.
        max_t: maximum range in cells.
    """
    n, b = psi.shape
    out = np.empty((n, b))
    for i in range(n):
        v0, u0 = start[i, 0], start[i, 1]
        for j in range(b):
            # map frame: x right, y up; grid: column u right, row v down
            t = _walk(blocked, v0, u0, -math.sin(psi[i, j]), math.cos(psi[i, j]), max_t)
            out[i, j] = min(t, max_t)
    return out


@numba.njit(cache=True, nogil=True)
def cast_centres(
    blocked: np.ndarray, cells: np.ndarray, angle: float, max_t: float, scale: float, result: np.ndarray
) -> None:
    """``result[i]``: ``min(range, max_t)·scale`` from the centre of ``cells[i]`` along ``angle``.

    Args:
        blocked: ``(rows, cols)`` bool blocking mask (image orientation).
        cells: ``(N, 2)`` int ``(row, col)`` start cells.
        angle: map-frame ray angle, radians counter-clockwise from +x.
        max_t: maximum range in cells.
        scale: multiplies every range (cells) on output.
        result: ``(N,)`` float32, filled.
    """
    dv, du = -math.sin(angle), math.cos(angle)
    for i in range(cells.shape[0]):
        t = _walk(blocked, cells[i, 0] + 0.5, cells[i, 1] + 0.5, dv, du, max_t)
        result[i] = min(t, max_t) * scale


@numba.njit(cache=True, nogil=True)
def _walk(blocked: np.ndarray, v0: float, u0: float, dv: float, du: float, max_t: float) -> float:
    """Ray parameter (cells) where the ray enters its first blocking cell; ``inf`` if none.

    (No helper takes ``blocked`` inside the loop: numba would count references at every call.)
    """
    rows, cols = np.uint64(blocked.shape[0]), np.uint64(blocked.shape[1])
    t_in, t_out = _slab(v0, u0, dv, du, blocked.shape[0], blocked.shape[1])
    t_stop = min(max_t, t_out)
    if t_in > t_stop:
        return math.inf
    # a sensor exactly on a grid line is in the cell its ray enters; outside the map the
    # walk simply crosses empty cells until it reaches it
    r = math.floor(v0 + START_NUDGE * dv)
    c = math.floor(u0 + START_NUDGE * du)
    if _inside(r, c, rows, cols) and blocked[r, c]:
        return 0.0
    step_c = 1 if du > 0 else -1
    step_r = 1 if dv > 0 else -1
    next_u = (c + 1 - u0) / du if du > 0 else ((u0 - c) / -du if du < 0 else math.inf)
    next_v = (r + 1 - v0) / dv if dv > 0 else ((v0 - r) / -dv if dv < 0 else math.inf)
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
            rn = math.floor(v + 0.5)
            if abs(v - rn) < CORNER_EPS:
                if np.uint64(c) < cols and (
                    (np.uint64(rn - 1) < rows and blocked[rn - 1, c])
                    or (np.uint64(rn) < rows and blocked[rn, c])
                ):
                    return t
            elif _inside(r, c, rows, cols) and blocked[r, c]:
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
            cn = math.floor(u + 0.5)
            if abs(u - cn) < CORNER_EPS:
                if np.uint64(r) < rows and (
                    (np.uint64(cn - 1) < cols and blocked[r, cn - 1])
                    or (np.uint64(cn) < cols and blocked[r, cn])
                ):
                    return t
            elif _inside(r, c, rows, cols) and blocked[r, c]:
                return t


@numba.njit(cache=True, nogil=True)
def _inside(r: int, c: int, rows: np.uint64, cols: np.uint64) -> bool:
    """Whether cell ``(r, c)`` lies in a ``rows × cols`` grid."""
    return bool(np.uint64(r) < rows and np.uint64(c) < cols)


@numba.njit(cache=True, nogil=True)
def _slab(v0: float, u0: float, dv: float, du: float, rows: int, cols: int) -> tuple[float, float]:
    """Ray parameters where the ray enters and leaves the map grown by CORNER_EPS (``t_in > t_out``: never).

    Cells on the map's edge can be touched at their corners from just outside it.
    """
    e = CORNER_EPS
    t_in, t_out = -math.inf, math.inf
    for axis in range(2):
        p0, d, hi = (v0, dv, rows) if axis == 0 else (u0, du, cols)
        if d == 0.0:
            if not -e <= p0 <= hi + e:
                return math.inf, -math.inf
            continue
        a, b = (-e - p0) / d, (hi + e - p0) / d
        t_in, t_out = max(t_in, min(a, b)), min(t_out, max(a, b))
    return t_in, t_out
