"""Ray casting: known geometry, the fast casters against the cell-by-cell reference, noise, errors.

Tolerance. All three casters implement the same exact semantics (entry point of the first
blocking cell, corners closed): they differ only by float64 rounding of the ray geometry
(~1e-12 cells) and the float32 output. So fast and reference ranges are asserted equal to
``TOL`` (1 µm + float32 rounding) on *every* beam, not "within a cell for most beams": a
ray that slips through a gap or stops a cell early would show up. Rays through an exact
grid corner are not a special case here because every caster treats a corner as touching
all four cells around it (45° beams from cell centres hit corners at every step).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from knowledge.metric import OccupancyGrid
from knowledge.metric.raycast import beam_angles, cast, cast_cells, reference_cast


def tol(max_range: float) -> float:
    """Agreement asserted between casters: float32 rounding of ranges up to ``max_range`` plus 1 µm."""
    return 1e-6 + 2.0 * max_range * float(np.finfo(np.float32).eps)


def room(
    rows: int = 40,
    cols: int = 60,
    res: float = 0.1,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    door: slice | None = None,
) -> OccupancyGrid:
    """A closed rectangular room: one-cell walls on the border, optionally a door in the right wall."""
    occ = np.zeros((rows, cols), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    if door is not None:
        occ[door, -1] = False
    return OccupancyGrid.from_masks(occ, res, origin=origin, name="room")


def map_to_world(grid: OccupancyGrid, mx: float, my: float) -> tuple[float, float]:
    """World coordinates of the map-frame point ``(mx, my)``."""
    ox, oy, yaw = grid.origin
    return ox + math.cos(yaw) * mx - math.sin(yaw) * my, oy + math.sin(yaw) * mx + math.cos(yaw) * my


def box_distance(
    px: float, py: float, angles: np.ndarray, x0: float, y0: float, x1: float, y1: float
) -> np.ndarray:
    """Distance from ``(px, py)`` inside the box ``[x0, x1] × [y0, y1]`` to its boundary along each angle."""
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (x1 - px) / c, np.where(c < 0, (x0 - px) / c, np.inf))
        ty = np.where(s > 0, (y1 - py) / s, np.where(s < 0, (y0 - py) / s, np.inf))
    return np.minimum(tx, ty)


# ---------------------------------------------------------------------------------------- beams
def test_beam_angles_full_circle_and_sick() -> None:
    a = beam_angles(360)
    assert a.shape == (360,) and a[0] == 0.0
    assert np.allclose(np.diff(a), math.radians(1.0)) and a[-1] < 2 * math.pi - 1e-9
    sick = beam_angles(361, math.pi)
    assert sick[0] == pytest.approx(-math.pi / 2) and sick[-1] == pytest.approx(math.pi / 2)
    assert np.allclose(np.diff(sick), math.radians(0.5))
    assert beam_angles(4, angle_min=1.0)[0] == 1.0
    assert beam_angles(3, math.pi, angle_min=0.0).tolist() == pytest.approx([0.0, math.pi / 2, math.pi])


# --------------------------------------------------------------------------------- known geometry
@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (3.0, -2.0, 0.7)])
def test_closed_room_matches_analytic_walls(origin: tuple[float, float, float]) -> None:
    grid = room(origin=origin)
    res = grid.resolution
    # the free inside spans map x in [res, 59·res], y in [res, 39·res]
    mx, my, heading = 2.33, 1.71, 0.4
    px, py = map_to_world(grid, mx, my)
    ranges = cast(grid, np.array([px, py, heading + origin[2]]), n_beams=180, max_range=30.0)
    expected = box_distance(mx, my, beam_angles(180) + heading, res, res, 59 * res, 39 * res)
    assert ranges.shape == (180,) and ranges.dtype == np.float32
    assert np.abs(ranges - expected).max() <= tol(30.0)
    assert np.abs(
        reference_cast(grid, np.array([px, py, heading + origin[2]]), n_beams=180) - expected
    ).max() <= tol(30.0)


def test_beam_through_open_door_escapes() -> None:
    grid = room(door=slice(18, 23))  # rows 18..22 of the right wall are open
    res = grid.resolution
    my = (40 - 20.5) * res  # the centre row of the door
    ranges = cast(grid, np.array([[1.0, my, 0.0], [1.0, my + 0.5, 0.0]]), n_beams=4, max_range=12.0)
    assert ranges[0, 0] == np.float32(12.0), "beam through the door leaves the map: max_range"
    assert ranges[1, 0] == pytest.approx(59 * res - 1.0, abs=tol(12.0)), "beam beside the door hits the wall"
    # an exact 12.0 for a miss, not merely close to it
    assert cast(grid, np.array([1.0, my, 0.0]), n_beams=1, max_range=7.5)[0] == np.float32(7.5)


def test_ray_along_a_wall_is_not_stopped_by_it() -> None:
    grid = room()
    res = grid.resolution
    # centre of the cell next to the bottom wall, beams along the wall both ways
    my = 1.5 * res
    for mx, heading, expected in ((5.5 * res, 0.0, 59 * res - 5.5 * res), (50.5 * res, math.pi, 49.5 * res)):
        pose = np.array([mx, my, heading])
        assert cast(grid, pose, n_beams=1)[0] == pytest.approx(expected, abs=tol(30.0))
        assert reference_cast(grid, pose, n_beams=1)[0] == pytest.approx(expected, abs=tol(30.0))
    fc = np.array([[38, 5]])  # the same cell, as a cast_cells start: beam 0 points along +x
    assert cast_cells(grid, fc, n_beams=4)[0, 0] == pytest.approx(59 * res - 5.5 * res, abs=tol(30.0))


def test_pose_inside_an_obstacle_sees_zero() -> None:
    grid = room()
    pose = np.array([0.05, 2.0, 1.0])  # inside the left wall
    assert np.all(cast(grid, pose, n_beams=36) == 0.0)
    assert np.all(reference_cast(grid, pose, n_beams=36) == 0.0)
    assert np.all(cast_cells(grid, np.array([[20, 0]]), n_beams=36) == 0.0)


def test_unknown_cells_block_only_when_asked() -> None:
    occ = np.zeros((10, 30), dtype=bool)
    unk = np.zeros_like(occ)
    unk[:, 20] = True
    grid = OccupancyGrid.from_masks(occ, 0.1, unknown=unk)
    pose = np.array([0.55, 0.55, 0.0])
    assert cast(grid, pose, n_beams=1)[0] == pytest.approx(1.45, abs=tol(30.0))
    assert cast(grid, pose, n_beams=1, unknown_blocks=False)[0] == np.float32(30.0)
    assert cast_cells(grid, np.array([[4, 5]]), n_beams=1, unknown_blocks=False)[0, 0] == np.float32(30.0)


def test_diagonal_rays_do_not_slip_between_corner_touching_cells() -> None:
    # two blocking cells that meet only at a corner, straddling a 45° ray from a cell centre
    occ = np.zeros((12, 12), dtype=bool)
    occ[4, 7] = occ[5, 8] = True  # (row, col): the corner they share is at map (x, y) = (8, 7) cells
    grid = OccupancyGrid.from_masks(occ, 0.2)
    start = np.array([[10, 2]])  # centre at map (2.5, 1.5) cells: the 45° ray passes through (8, 7)
    expected = math.sqrt(2) * 5.5 * 0.2
    beam45 = cast_cells(grid, start, n_beams=8)[0, 1]
    pose = np.column_stack([grid.cell_to_world(start), [0.0]])
    assert beam45 == pytest.approx(expected, abs=tol(30.0))
    assert cast(grid, pose, n_beams=8)[0, 1] == pytest.approx(expected, abs=tol(30.0))
    assert reference_cast(grid, pose, n_beams=8)[0, 1] == pytest.approx(expected, abs=tol(30.0))


def test_shapes_fov_and_single_pose() -> None:
    grid = room()
    poses = np.array([[2.0, 2.0, 0.0], [3.0, 1.0, 1.0]])
    assert cast(grid, poses, n_beams=361, fov=math.pi).shape == (2, 361)
    assert cast(grid, poses[0], n_beams=5).shape == (5,)
    assert cast(grid, np.zeros((0, 3)), n_beams=5).shape == (0, 5)
    assert cast_cells(grid, np.zeros((0, 2), dtype=np.int64), n_beams=5).shape == (0, 5)
    # a 180° scan is the matching half of a full scan: beam k of SICK = beam 270 + k/2 of a 720-beam circle
    half = cast(grid, poses, n_beams=361, fov=math.pi)
    full = cast(grid, poses, n_beams=720)
    assert np.abs(half - np.concatenate([full[:, 540:], full[:, :181]], axis=1)).max() <= tol(30.0)


# ------------------------------------------------------------------------------ fast vs reference
@st.composite
def small_maps(draw: st.DrawFn) -> OccupancyGrid:
    rows = draw(st.integers(1, 18))
    cols = draw(st.integers(1, 18))
    seed = draw(st.integers(0, 2**32 - 1))
    density = draw(st.sampled_from([0.0, 0.05, 0.2, 0.5]))
    rng = np.random.default_rng(seed)
    occ = rng.random((rows, cols)) < density
    unk = rng.random((rows, cols)) < draw(st.sampled_from([0.0, 0.1]))
    res = draw(st.sampled_from([0.05, 0.1, 0.37, 1.0]))
    origin = (
        draw(st.floats(-5, 5, allow_nan=False)),
        draw(st.floats(-5, 5, allow_nan=False)),
        draw(st.sampled_from([0.0, 0.3, -2.0, math.pi / 2])),
    )
    return OccupancyGrid.from_masks(occ, res, unknown=unk, origin=origin)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    grid=small_maps(),
    data=st.data(),
    n_beams=st.integers(1, 40),
    max_range=st.sampled_from([0.3, 2.0, 50.0]),
)
def test_cast_equals_reference_on_random_maps(
    grid: OccupancyGrid, data: st.DataObject, n_beams: int, max_range: float
) -> None:
    rows, cols = grid.shape
    # poses anywhere in and a little around the map (continuous cell coordinates → world)
    rc = data.draw(
        st.lists(
            st.tuples(st.floats(-1.5, rows + 1.5), st.floats(-1.5, cols + 1.5), st.floats(-7, 7)),
            min_size=1,
            max_size=4,
        )
    )
    v = np.array([p[0] for p in rc])
    u = np.array([p[1] for p in rc])
    xy = np.stack(
        [
            map_to_world(grid, uu * grid.resolution, (rows - vv) * grid.resolution)
            for vv, uu in zip(v, u, strict=True)
        ]
    )
    poses = np.column_stack([xy, [p[2] for p in rc]])
    fast = cast(grid, poses, n_beams=n_beams, max_range=max_range)
    ref = reference_cast(grid, poses, n_beams=n_beams, max_range=max_range)
    assert np.abs(fast - ref).max() <= tol(max_range)
    assert fast.min() >= 0.0 and fast.max() <= max_range


def slab_ranges(grid: OccupancyGrid, pose: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
    """An oracle that shares no code with the casters: the distance to every blocking cell,
    each cell an axis-aligned square in the map frame, by the slab method; the nearest wins.
    O(cells × beams), no grid walk."""
    from knowledge.metric.beams import blocking_mask

    ox, oy, yaw = grid.origin
    res = grid.resolution
    rows, _ = grid.shape
    # the sensor in the map frame (x right, y up, from the map's lower-left corner)
    dx, dy = pose[0] - ox, pose[1] - oy
    mx, my = math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy
    r, c = np.nonzero(blocking_mask(grid, True))
    x0, x1 = c * res, (c + 1) * res
    y0, y1 = (rows - 1 - r) * res, (rows - r) * res
    out = np.full(angles.shape, max_range)
    for j, a in enumerate(pose[2] + angles - yaw):
        ux, uy = math.cos(a), math.sin(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            tx0, tx1 = (x0 - mx) / ux, (x1 - mx) / ux
            ty0, ty1 = (y0 - my) / uy, (y1 - my) / uy
        if ux == 0.0:  # parallel to the x slabs: inside them or never
            inside = (x0 <= mx) & (mx <= x1)
            tx0, tx1 = np.where(inside, -np.inf, np.inf), np.where(inside, np.inf, -np.inf)
        if uy == 0.0:
            inside = (y0 <= my) & (my <= y1)
            ty0, ty1 = np.where(inside, -np.inf, np.inf), np.where(inside, np.inf, -np.inf)
        enter = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
        leave = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
        hit = (enter <= leave) & (leave > 0)
        if hit.any():
            out[j] = min(max_range, float(np.maximum(enter[hit], 0.0).min()))
    return out


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    grid=small_maps(),
    seed=st.integers(0, 2**32 - 1),
    n_beams=st.integers(1, 30),
    max_range=st.sampled_from([0.3, 2.0, 50.0]),
)
def test_cast_equals_an_independent_slab_oracle(
    grid: OccupancyGrid, seed: int, n_beams: int, max_range: float
) -> None:
    """The pose caster against geometry computed another way (the reference walks the grid
    as the caster does, so it is not independent). Continuous random poses and headings (from
    a seeded generator, not hypothesis' boundary values): no ray starts on a grid line or
    meets a corner exactly, where the casters' closed-corner and start-cell rules would
    differ from plain squares."""
    rows, cols = grid.shape
    res = grid.resolution
    rng = np.random.default_rng(seed)
    mxy = (rng.uniform(-1.5, cols + 1.5), rng.uniform(-1.5, rows + 1.5), rng.uniform(-7, 7))
    x, y = map_to_world(grid, mxy[0] * res, mxy[1] * res)
    pose = np.array([x, y, mxy[2]])
    got = cast(grid, pose, n_beams=n_beams, max_range=max_range)
    want = slab_ranges(grid, pose, beam_angles(n_beams), max_range)
    assert np.abs(got - want).max() <= tol(max_range) + 1e-9 * res


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    grid=small_maps(),
    n_beams=st.sampled_from([1, 3, 8, 24, 37, 72]),
    max_range=st.sampled_from([0.5, 3.0, 50.0]),
)
def test_cast_cells_equals_cast_and_reference(grid: OccupancyGrid, n_beams: int, max_range: float) -> None:
    cells = grid.free_cells()
    swept = cast_cells(grid, n_beams=n_beams, max_range=max_range)
    assert swept.shape == (len(cells), n_beams) and swept.dtype == np.float32
    if not len(cells):
        return
    # cast_cells works in the map frame: beam 0 along the map's +x, i.e. world heading = yaw
    poses = np.column_stack([grid.cell_to_world(cells), np.full(len(cells), grid.yaw)])
    assert np.abs(swept - cast(grid, poses, n_beams=n_beams, max_range=max_range)).max() <= tol(max_range)
    sample = np.random.default_rng(0).choice(len(cells), min(len(cells), 25), replace=False)
    ref = reference_cast(grid, poses[sample], n_beams=n_beams, max_range=max_range)
    assert np.abs(swept[sample] - ref).max() <= tol(max_range)


def test_cast_cells_on_corridors_and_diagonal_walls(rng: np.random.Generator) -> None:
    """Long walls at all angles: rays grazing them exercise the sweep's row skipping."""
    occ = np.zeros((70, 90), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[30, 5:80] = True  # a long corridor wall
    occ[31:60, 60] = True
    for i in range(35):  # a staircase diagonal wall and a shallow one
        occ[35 + i // 2, 10 + i] = True
        occ[5 + i, 45 + i] = True
    occ |= rng.random(occ.shape) < 0.005
    grid = OccupancyGrid.from_masks(occ, 0.05, origin=(1.0, 2.0, -0.4))
    cells = grid.free_cells()
    swept = cast_cells(grid, n_beams=360, max_range=4.0)
    poses = np.column_stack([grid.cell_to_world(cells), np.full(len(cells), grid.yaw)])
    sample = rng.choice(len(cells), 400, replace=False)
    fast = cast(grid, poses[sample], n_beams=360, max_range=4.0)
    assert np.abs(swept[sample] - fast).max() <= tol(4.0)
    few = sample[:8]
    assert np.abs(swept[few] - reference_cast(grid, poses[few], n_beams=360, max_range=4.0)).max() <= tol(4.0)


def test_cast_cells_diagonal_beams_through_grid_corners(rng: np.random.Generator) -> None:
    """45° beams from cell centres pass exactly through grid corners at every step: every beam, exact."""
    occ = rng.random((23, 29)) < 0.3
    grid = OccupancyGrid.from_masks(occ, 0.1, origin=(0.5, -1.0, 0.2))
    cells = grid.free_cells()
    swept = cast_cells(grid, n_beams=8, max_range=50.0)  # 4 of the 8 beams are diagonals
    poses = np.column_stack([grid.cell_to_world(cells), np.full(len(cells), grid.yaw)])
    assert np.abs(swept - reference_cast(grid, poses, n_beams=8, max_range=50.0)).max() <= tol(50.0)
    # a diagonal beam from a cell whose diagonal neighbour blocks stops at the shared corner
    r, c = next((r, c) for r, c in cells if r > 0 and c + 1 < occ.shape[1] and occ[r - 1, c + 1])
    row = int(np.flatnonzero((cells[:, 0] == r) & (cells[:, 1] == c))[0])
    assert swept[row, 1] == pytest.approx(math.sqrt(2) * 0.5 * 0.1, abs=tol(50.0))


def test_cast_cells_in_any_order_with_repeats_and_blocked_starts(rng: np.random.Generator) -> None:
    occ = rng.random((17, 21)) < 0.2
    grid = OccupancyGrid.from_masks(occ, 0.05)
    every = np.argwhere(np.ones(occ.shape, dtype=bool))  # free and blocked cells, row-major
    full = cast_cells(grid, every, n_beams=37, max_range=2.0)
    pick = rng.choice(len(every), 300)  # shuffled, with repeats
    assert np.array_equal(cast_cells(grid, every[pick], n_beams=37, max_range=2.0), full[pick])
    assert np.all(full[occ.ravel()] == 0.0), "a start inside a blocking cell sees nothing"
    poses = np.column_stack([grid.cell_to_world(every), np.zeros(len(every))])
    assert np.abs(full - cast(grid, poses, n_beams=37, max_range=2.0)).max() <= tol(2.0)


def test_cast_cells_on_a_map_too_long_for_the_sweep_tables() -> None:
    """Beams marching over more than 32 766 cells are walked ray by ray, with the same results."""
    occ = np.zeros((3, 33_000), dtype=bool)
    occ[0, 20_000] = occ[2, 32_990] = occ[1, 100] = True
    grid = OccupancyGrid.from_masks(occ, 0.1)
    cells = np.array([[1, 0], [1, 101], [0, 12_000], [2, 32_000], [1, 32_999]])
    swept = cast_cells(grid, cells, n_beams=16, max_range=4000.0)
    poses = np.column_stack([grid.cell_to_world(cells), np.zeros(len(cells))])
    assert np.abs(swept - cast(grid, poses, n_beams=16, max_range=4000.0)).max() <= tol(4000.0)
    assert swept[0, 0] == pytest.approx(9.95, abs=tol(4000.0)), "along the row to the cell at column 100"
    assert swept[1, 0] == np.float32(4000.0), "row 1 is clear to the map's end: leaving the map is a miss"


@pytest.mark.data
def test_cast_cells_on_a_real_map(shared_data: Path, rng: np.random.Generator) -> None:
    grid = OccupancyGrid.from_image(shared_data / "ipa" / "labeled" / "lab_intel.map.png", 0.05)
    cells = grid.free_cells()
    pick = cells[rng.choice(len(cells), 300, replace=False)]
    swept = cast_cells(grid, pick, n_beams=60, max_range=30.0)
    poses = np.column_stack([grid.cell_to_world(pick), np.zeros(len(pick))])
    assert np.abs(swept - cast(grid, poses, n_beams=60, max_range=30.0)).max() <= tol(30.0)
    assert (swept < 30.0).mean() > 0.95, "lab_intel is a closed building: nearly every beam hits"


def test_cast_cells_default_order_progress_and_out() -> None:
    grid = room(rows=8, cols=9)
    calls: list[tuple[int, int]] = []
    all_cells = cast_cells(grid, n_beams=40, progress=lambda d, t: calls.append((d, t)))
    assert np.array_equal(all_cells, cast_cells(grid, grid.free_cells(), n_beams=40))
    assert [d for d, _ in calls] == list(range(1, 41)) and {t for _, t in calls} == {40}
    buf = np.full(all_cells.shape, np.nan, dtype=np.float32)
    assert cast_cells(grid, n_beams=40, out=buf) is buf and np.array_equal(buf, all_cells)
    with pytest.raises(ValueError, match="out must be"):
        cast_cells(grid, n_beams=40, out=np.empty(all_cells.shape, dtype=np.float64))


# ----------------------------------------------------------------------------------------- noise
def test_noise_statistics_seeding_and_misses() -> None:
    grid = room(rows=200, cols=200, res=0.05, door=slice(90, 111))
    poses = np.array([[5.0, 5.0, 0.0]] * 40)
    clean = cast(grid, poses, n_beams=360, max_range=8.0)
    noisy = cast(grid, poses, n_beams=360, max_range=8.0, noise_std=0.05, rng=np.random.default_rng(1))
    again = cast(grid, poses, n_beams=360, max_range=8.0, noise_std=0.05, rng=np.random.default_rng(1))
    assert np.array_equal(noisy, again), "a seeded generator reproduces the scan"
    miss = clean == np.float32(8.0)
    assert miss.any() and (~miss).sum() > 5000
    assert np.all(noisy[miss] == np.float32(8.0)), "beams that hit nothing stay at max_range"
    err = (noisy - clean)[~miss & (clean < 7.5)].astype(np.float64)
    assert abs(err.mean()) < 4 * 0.05 / math.sqrt(err.size)
    assert err.std() == pytest.approx(0.05, rel=0.05)
    wild = cast(grid, poses[:2], n_beams=360, max_range=8.0, noise_std=5.0, rng=np.random.default_rng(2))
    assert wild.min() >= 0.0 and wild.max() <= 8.0, "noisy ranges are clipped to [0, max_range]"


# ----------------------------------------------------------------------------------- bad arguments
@pytest.mark.parametrize("n_beams", [0, -3, 2.5, True])
def test_bad_n_beams(n_beams: object) -> None:
    grid = room()
    with pytest.raises(ValueError, match="n_beams"):
        cast(grid, np.zeros(3), n_beams=n_beams)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_beams"):
        cast_cells(grid, n_beams=n_beams)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_beams"):
        beam_angles(n_beams)  # type: ignore[arg-type]


@pytest.mark.parametrize("max_range", [0.0, -1.0, math.nan, math.inf])
def test_bad_max_range(max_range: float) -> None:
    grid = room()
    with pytest.raises(ValueError, match="max_range"):
        cast(grid, np.zeros(3), max_range=max_range)
    with pytest.raises(ValueError, match="max_range"):
        cast_cells(grid, max_range=max_range)
    with pytest.raises(ValueError, match="max_range"):
        reference_cast(grid, np.zeros(3), max_range=max_range)


@pytest.mark.parametrize("poses", [np.zeros(2), np.zeros((4, 2)), np.zeros((2, 4)), np.zeros((1, 1, 3))])
def test_bad_pose_shape(poses: np.ndarray) -> None:
    with pytest.raises(ValueError, match=r"poses must be \(N, 3\)"):
        cast(room(), poses)


def test_other_bad_arguments() -> None:
    grid = room()
    with pytest.raises(ValueError, match="finite"):
        cast(grid, np.array([0.0, math.nan, 0.0]))
    with pytest.raises(ValueError, match="noise_std"):
        cast(grid, np.zeros(3), noise_std=-0.1)
    with pytest.raises(ValueError, match="fov"):
        cast(grid, np.zeros(3), fov=7.0)
    with pytest.raises(ValueError, match="inside"):
        cast_cells(grid, np.array([[0, 60]]))
    with pytest.raises(ValueError, match=r"\(N, 2\) integer"):
        cast_cells(grid, np.array([[1.5, 2.0]]))
