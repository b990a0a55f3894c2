"""Beam geometry and argument checks shared by the ray casters.

A scan is ``n_beams`` rays at fixed angles relative to the sensor heading (radians,
counter-clockwise). :func:`beam_angles` fixes those angles; the helpers below turn the
arguments every caster takes into checked arrays, so the fast casters and the reference
caster reject bad input with the same messages.
"""

from __future__ import annotations

import math

import numpy as np

from knowledge.metric.grid import OccupancyGrid

TWO_PI = 2.0 * math.pi

#: Cells: a ray passing closer than this to a grid corner touches every cell meeting there
#: (so no ray slips diagonally between two blocking cells that share only a corner).
CORNER_EPS = 1e-9


def beam_angles(n_beams: int, fov: float = TWO_PI, angle_min: float | None = None) -> np.ndarray:
    """``(n_beams,)`` float64 beam angles in radians relative to the sensor heading.

    For a full circle (``fov`` = 2π) beam ``i`` is at ``angle_min + i·2π/n_beams`` with
    ``angle_min`` defaulting to 0 (no duplicated beam at 2π). For ``fov`` < 2π the beams
    span ``[angle_min, angle_min + fov]`` inclusive, ``angle_min`` defaulting to ``-fov/2``
    (a SICK 180° scan: ``beam_angles(361, math.pi)`` is -90° … +90° in 0.5° steps).
    """
    n = check_n_beams(n_beams)
    if not (math.isfinite(fov) and 0.0 < fov <= TWO_PI + 1e-12):
        raise ValueError(f"fov must be in (0, 2π] radians, got {fov}")
    if angle_min is not None and not math.isfinite(angle_min):
        raise ValueError(f"angle_min must be a finite angle in radians, got {angle_min}")
    if fov >= TWO_PI - 1e-12:
        start = 0.0 if angle_min is None else float(angle_min)
        return start + np.arange(n, dtype=np.float64) * (TWO_PI / n)
    start = -fov / 2.0 if angle_min is None else float(angle_min)
    if n == 1:
        return np.array([start])
    return start + np.arange(n, dtype=np.float64) * (fov / (n - 1))


def check_n_beams(n_beams: int) -> int:
    """``n_beams`` as an int ≥ 1, or a ValueError that says so."""
    if isinstance(n_beams, bool) or not isinstance(n_beams, int | np.integer) or n_beams < 1:
        raise ValueError(f"n_beams must be a positive integer, got {n_beams!r}")
    return int(n_beams)


def check_max_range(max_range: float) -> float:
    """``max_range`` in metres as a positive finite float, or a ValueError."""
    r = float(max_range)
    if not (math.isfinite(r) and r > 0.0):
        raise ValueError(f"max_range must be a positive number of metres, got {max_range!r}")
    return r


def as_poses(poses: np.ndarray) -> tuple[np.ndarray, bool]:
    """Poses as an ``(N, 3)`` float64 array of world ``x, y`` [m] and heading θ [rad].

    Returns the array and whether a single ``(3,)`` pose was given (the caller then
    returns one scan instead of a batch of one).
    """
    p = np.asarray(poses, dtype=np.float64)
    single = p.ndim == 1
    if single:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(
            f"poses must be (N, 3) rows of x [m], y [m], heading [rad] (or one (3,) pose), got shape {np.shape(poses)}"
        )
    if not np.isfinite(p).all():
        raise ValueError("poses must be finite (no NaN or inf)")
    return p, single


def blocking_mask(grid: OccupancyGrid, unknown_blocks: bool) -> np.ndarray:
    """``(rows, cols)`` bool: the cells that stop a ray (occupied; unknown too if asked)."""
    return (grid.state != 0) if unknown_blocks else grid.occupied


def map_frame_directions(grid: OccupancyGrid, headings: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """``(N, B)`` map-frame ray angles: world heading plus beam angle minus the map's yaw."""
    return headings[:, None] + angles[None, :] - grid.yaw
