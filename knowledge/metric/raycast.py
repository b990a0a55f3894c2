"""Ray casting of laser scans in occupancy grids.

:func:`cast` simulates scans from any poses (the simulator, tests); :func:`cast_cells`
casts a full circle of beams from the centres of many grid cells at once (whole-map place
labeling); :func:`reference_cast` is the slow cell-by-cell walk both are tested against.
The two fast casters are compiled with numba (single-threaded, cached on disk next to
their modules).

Semantics (all three casters agree on them):

- Lengths are in metres, angles in radians. A pose is world ``x, y`` and heading θ; beam
  ``i`` points at ``θ + beam_angles(...)[i]`` in the world frame. The grid's ``origin``
  (x, y, yaw) is honoured through its transforms.
- A range is the distance from the sensor to the point where the ray *enters* the first
  blocking cell: occupied cells, and unknown cells too when ``unknown_blocks``.
- The ray starts inside its own cell: if that cell blocks, the range is 0.
- Cells are closed at their corners: a ray passing within 10⁻⁹ cell of a grid corner
  touches every cell meeting there, so no ray slips diagonally between two blocking cells
  that share only a corner (45° beams from cell centres pass exactly through corners).
- A sensor exactly on a grid line is in the cell its ray enters (the cell 10⁻⁹ cell along
  the ray); a blocking cell it merely touches at its start point does not stop the ray.
- Leaving the map counts as hitting nothing. A beam that hits nothing within
  ``max_range`` returns exactly ``max_range``; hits beyond it are reported as misses.
- Noise (:func:`cast` only) is additive Gaussian with standard deviation ``noise_std``
  metres, added only to beams that hit something, then clipped to ``[0, max_range]``.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable

import numpy as np

from knowledge.metric.beams import (
    as_poses,
    beam_angles,
    blocking_mask,
    check_max_range,
    check_n_beams,
    map_frame_directions,
)
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.raycast_poses import cast_rays
from knowledge.metric.raycast_reference import reference_cast
from knowledge.metric.raycast_sweep import sweep_cells

__all__ = ["beam_angles", "cast", "cast_cells", "reference_cast"]

#: Per map: its blocking masks (with and without unknown cells), made once for :func:`cast`.
_MASKS: weakref.WeakKeyDictionary[OccupancyGrid, dict[bool, np.ndarray]] = weakref.WeakKeyDictionary()


def cast(
    grid: OccupancyGrid,
    poses: np.ndarray,
    *,
    n_beams: int = 360,
    max_range: float = 30.0,
    fov: float = 2.0 * math.pi,
    angle_min: float | None = None,
    noise_std: float = 0.0,
    rng: np.random.Generator | None = None,
    unknown_blocks: bool = True,
) -> np.ndarray:
    """Simulated laser scans from ``poses``.

    Args:
        grid: the map.
        poses: ``(N, 3)`` world ``x`` [m], ``y`` [m], heading θ [rad]; or one ``(3,)`` pose.
        n_beams: beams per scan, at :func:`beam_angles` ``(n_beams, fov, angle_min)``.
        max_range: sensor range in metres.
        fov, angle_min: field of view and first beam angle, radians (see :func:`beam_angles`).
        noise_std: standard deviation in metres of Gaussian noise on beams that hit something.
        rng: random generator for the noise (a fresh unseeded one if None).
        unknown_blocks: unknown cells stop rays as occupied ones do.

    Returns:
        ``(N, n_beams)`` float32 ranges in metres (``(n_beams,)`` for one ``(3,)`` pose).
    """
    p, single = as_poses(poses)
    angles = beam_angles(check_n_beams(n_beams), fov, angle_min)
    max_range = check_max_range(max_range)
    if not (math.isfinite(noise_std) and noise_std >= 0.0):
        raise ValueError(f"noise_std must be a non-negative number of metres, got {noise_std!r}")
    max_t = max_range / grid.resolution
    start = grid.world_to_cell_float(p[:, :2])
    psi = map_frame_directions(grid, p[:, 2], angles)
    t = cast_rays(_mask(grid, unknown_blocks), np.ascontiguousarray(start), np.ascontiguousarray(psi), max_t)
    ranges = t * grid.resolution
    if noise_std > 0.0:
        gen = rng if rng is not None else np.random.default_rng()
        hit = t < max_t
        ranges[hit] = np.clip(ranges[hit] + gen.normal(0.0, noise_std, int(hit.sum())), 0.0, max_range)
    out = ranges.astype(np.float32)
    return out[0] if single else out


def cast_cells(
    grid: OccupancyGrid,
    cells: np.ndarray | None = None,
    *,
    n_beams: int = 360,
    max_range: float = 30.0,
    unknown_blocks: bool = True,
    progress: Callable[[int, int], None] | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Full-circle scans from the centres of grid cells, in the map frame.

    Beam ``i`` points at ``i·2π/n_beams`` counter-clockwise from the map's +x axis (so
    this equals :func:`cast` at the cell centres with heading = the map's yaw).

    Args:
        grid: the map.
        cells: ``(N, 2)`` int ``(row, col)``; None means every free cell in row-major order,
            as :meth:`OccupancyGrid.free_cells` returns them.
        n_beams: beams per scan.
        max_range: sensor range in metres.
        unknown_blocks: unknown cells stop rays as occupied ones do.
        progress: called as ``progress(done, total)`` after each beam direction.
        out: an ``(N, n_beams)`` C-contiguous float32 array to fill and return, e.g. to
            reuse one buffer across maps (a fresh array this size costs ~0.5 s of page
            faults for a whole 0.05 m building).

    Returns:
        ``(N, n_beams)`` float32 ranges in metres.

    Speed: one compiled directional sweep per beam (see :mod:`knowledge.metric.raycast_sweep`),
    ~1.5 s on one core for every free cell of a 0.05 m building (300 k cells × 360 beams,
    ~11 ns a ray) plus the page faults of a fresh result; its cost grows with the map's
    area per beam plus the number of rays, so casting a few cells of a big map is cheaper
    with :func:`cast`. The first call in a process loads the compiled code (~0.4 s; ~6 s
    to compile it when numba's on-disk cache is cold).
    """
    n_beams = check_n_beams(n_beams)
    max_range = check_max_range(max_range)
    if cells is None:
        rc = grid.free_cells()
    else:
        rc = np.asarray(cells)
        if rc.ndim != 2 or rc.shape[1] != 2 or not (rc.size == 0 or np.issubdtype(rc.dtype, np.integer)):
            raise ValueError(
                f"cells must be an (N, 2) integer array of (row, col), got shape {rc.shape} {rc.dtype}"
            )
        if not grid.in_bounds(rc).all():
            raise ValueError(f"cells must lie inside the {grid.shape[0]}x{grid.shape[1]} grid")
    angles = beam_angles(n_beams)
    if rc.shape[0] == 0:
        return np.empty((0, n_beams), dtype=np.float32) if out is None else out
    return sweep_cells(
        blocking_mask(grid, unknown_blocks),
        rc,
        angles,
        max_range / grid.resolution,
        scale=grid.resolution,
        progress=progress,
        out=out,
    )


def _mask(grid: OccupancyGrid, unknown_blocks: bool) -> np.ndarray:
    """The C-contiguous blocking mask of ``grid``, cached while the grid lives."""
    per_grid = _MASKS.setdefault(grid, {})
    if unknown_blocks not in per_grid:
        per_grid[unknown_blocks] = np.ascontiguousarray(blocking_mask(grid, unknown_blocks))
    return per_grid[unknown_blocks]
