"""Doorway detection (Sect. 7.2.2): passing through a door in a generated building gives one
doorway with the door's width and orientation; a corridor, furniture or turning back give none."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.metric.beams import beam_angles
from knowledge.metric.local_map import LocalMap
from knowledge.metric.raycast import cast
from knowledge.navigation.doorways import (
    Doorway,
    DoorwayDetector,
    DoorwayParams,
    measure_opening,
    scan_points,
)
from sim.buildings import Building, Door, generate_building

FULL = beam_angles(360)
SICK = beam_angles(361, math.pi)


@pytest.fixture(scope="module")
def building() -> Building:
    return generate_building(0)


def _clearance_ok(b: Building, xy: np.ndarray, margin: float = 0.25) -> bool:
    g = b.grid
    free = g.free
    for p in xy:
        r, c = g.world_to_cell(p)
        k = math.ceil(margin / g.resolution)
        if not free[max(0, r - k) : r + k + 1, max(0, c - k) : c + k + 1].all():
            return False
    return True


def crossing(b: Building, door: Door, reach: float = 1.5, step: float = 0.06) -> np.ndarray:
    """Poses along the door's normal through its centre, from ``-reach`` to ``+reach`` metres."""
    s = np.arange(-reach, reach + 1e-9, step)
    th = door.orientation
    cx, cy = door.center
    return np.column_stack((cx + s * math.cos(th), cy + s * math.sin(th), np.full(s.size, th)))


@pytest.fixture(scope="module")
def doors(building: Building) -> list[Door]:
    """Doors whose crossing path keeps clear of furniture (not every door has 1.5 m free behind it)."""
    out = [d for d in building.doors if _clearance_ok(building, crossing(building, d)[:, :2])]
    assert len(out) >= 5
    return out


def run_360(b: Building, poses: np.ndarray, det: DoorwayDetector | None = None) -> list[Doorway]:
    det = det or DoorwayDetector()
    scans = cast(b.grid, poses, n_beams=360, max_range=30.0, noise_std=0.01, rng=np.random.default_rng(1))
    found = []
    for k, (pose, r) in enumerate(zip(poses, scans, strict=True)):
        d = det.update(scan_points(r, FULL, range_max=30.0), pose, 0.1 * k)
        if d is not None:
            found.append(d)
    return found


def run_front(b: Building, poses: np.ndarray) -> list[Doorway]:
    """As the agent does with a front laser: the detector sees the local map's points."""
    det, m = DoorwayDetector(), LocalMap()
    scans = cast(
        b.grid, poses, n_beams=361, fov=math.pi, max_range=30.0, noise_std=0.01, rng=np.random.default_rng(2)
    )
    found = []
    for k, (pose, r) in enumerate(zip(poses, scans, strict=True)):
        m.add(r, SICK, pose, stamp=0.1 * k, range_max=30.0)
        d = det.update(m.points_in_robot_frame(pose), pose, 0.1 * k)
        if d is not None:
            found.append(d)
    return found


def test_a_door_stepped_over_between_two_sparse_scans_is_found(building: Building, doors: list[Door]) -> None:
    """A log with a scan every second: the front laser sees the door from 1.5 m before it, and
    the next scan comes 1.2 m beyond it. The detector measures at poses in between on the
    local map's points; measuring only at the scans (max_step 10 m) finds nothing."""
    door = doors[0]
    poses = crossing(building, door)
    sparse = poses[[0, 3, len(poses) - 5]]  # 1.5 m and 1.3 m before, then 1.2 m beyond
    scans = cast(building.grid, sparse, n_beams=361, fov=math.pi, max_range=30.0)
    found: dict[float, list[Doorway]] = {}
    for max_step in (0.25, 10.0):
        det, m = DoorwayDetector(DoorwayParams(max_step=max_step)), LocalMap()
        found[max_step] = []
        for k, (pose, r) in enumerate(zip(sparse, scans, strict=True)):
            m.add(r, SICK, pose, stamp=float(k), range_max=30.0)
            d = det.update(m.points_in_robot_frame(pose), pose, float(k))
            if d is not None:
                found[max_step].append(d)
    assert found[10.0] == []
    (d,) = found[0.25]
    assert math.dist(d.center, door.center) < 0.2 and d.width == pytest.approx(door.width, abs=0.1)
    assert 1.0 < d.stamp < 2.0  # measured between the second and the third scan


def _angle_diff(a: float, b: float) -> float:
    return abs(math.atan2(math.sin(a - b), math.cos(a - b)))


@pytest.mark.slow
@pytest.mark.parametrize("laser", ["360", "front"])
def test_one_doorway_per_door_passed(building: Building, doors: list[Door], laser: str) -> None:
    for door in doors:
        for direction in (1, -1):
            poses = crossing(building, door)[::direction].copy()
            if direction < 0:
                poses[:, 2] += math.pi
            found = run_360(building, poses) if laser == "360" else run_front(building, poses)
            assert len(found) == 1, (door.id, direction, found)
            d = found[0]
            assert math.hypot(d.center[0] - door.center[0], d.center[1] - door.center[1]) < 0.15
            assert d.width == pytest.approx(door.width, abs=0.06)
            # the normal points the way the robot went
            assert _angle_diff(d.orientation, poses[0, 2]) < math.radians(10)


def test_none_along_a_corridor(building: Building) -> None:
    # the longest straight corridor stretch, driven along its middle past every side door
    x0, y0, x1, y1 = max(
        (r for c in building.corridors for r in c.rects), key=lambda r: max(r[2] - r[0], r[3] - r[1])
    )
    if x1 - x0 >= y1 - y0:
        xs = np.arange(x0 + 0.5, x1 - 0.5, 0.06)
        poses = np.column_stack((xs, np.full(xs.size, (y0 + y1) / 2), np.zeros(xs.size)))
    else:
        ys = np.arange(y0 + 0.5, y1 - 0.5, 0.06)
        poses = np.column_stack((np.full(ys.size, (x0 + x1) / 2), ys, np.full(ys.size, math.pi / 2)))
    assert max(x1 - x0, y1 - y0) > 8.0
    assert run_360(building, poses) == []


def test_none_when_turning_back_in_the_door(building: Building, doors: list[Door]) -> None:
    door = doors[0]
    poses = crossing(building, door)
    half = poses[: len(poses) // 2 + 1]  # up to the door's centre
    back = half[::-1].copy()
    back[:, 2] += math.pi
    det = DoorwayDetector()
    assert run_360(building, np.concatenate((half, back)), det) == []
    assert not det.passing


def test_measure_opening_on_walls_and_on_isolated_obstacles() -> None:
    # a wall along y (x = 0 .. 0.15 thick) with a 0.9 m gap at |y| < 0.45, robot at the origin facing +x
    ys = np.concatenate((np.arange(-3.0, -0.45, 0.05), np.arange(0.5, 3.0, 0.05)))
    wall = np.column_stack((np.full(ys.size, -0.05), ys))
    jambs = np.array([[x, s * 0.45] for x in np.arange(-0.05, 0.11, 0.05) for s in (-1, 1)])
    pts = np.concatenate((wall, jambs))
    m = measure_opening(pts)
    assert m is not None and m.walls
    assert m.width == pytest.approx(0.9, abs=1e-9)
    assert m.normal[0] == pytest.approx(1.0, abs=1e-6)
    assert m.center[1] == pytest.approx(0.0, abs=1e-9)
    # two table legs 0.9 m apart: narrow, but no wall beyond them
    legs = np.array([[0.0, 0.45], [0.02, 0.47], [0.0, -0.45], [0.02, -0.47]])
    m = measure_opening(legs)
    assert m is not None and not m.walls
    # a corridor 1.6 m wide is not a door
    corridor = np.array([[x, s * 0.8] for x in np.arange(-2, 2, 0.05) for s in (-1, 1)])
    assert measure_opening(corridor) is None
    # one side only
    assert measure_opening(wall[wall[:, 1] > 0]) is None


def test_legs_alone_never_start_a_passage() -> None:
    legs = np.array([[0.0, 0.45], [0.0, -0.45]])
    det = DoorwayDetector()
    for x in np.arange(-1.0, 1.0, 0.05):
        assert det.update(legs - [x, 0.0], (x, 0.0, 0.0)) is None
        assert not det.passing


def test_params_are_checked() -> None:
    with pytest.raises(ValueError, match="min_width"):
        DoorwayParams(min_width=1.5, max_width=1.3)
    with pytest.raises(ValueError, match="band"):
        DoorwayParams(band=0.0)
    with pytest.raises(ValueError, match="pose"):
        DoorwayDetector().update(np.zeros((0, 2)), np.zeros(2))
