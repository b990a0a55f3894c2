"""Full 360° scans from a front laser (Sect. 3.5): resampling, rear beams from the local map,
interpolation of beams with no hit, and the 360° pass-through."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.metric.beams import beam_angles
from knowledge.metric.grid import OccupancyGrid
from knowledge.metric.local_map import LocalMap
from knowledge.metric.raycast import cast
from knowledge.metric.rear_beams import (
    FullScanParams,
    assemble_scan,
    full_scan,
    output_angles,
    resample,
    simulate_rear,
)

SICK = beam_angles(361, math.pi)
RES = 0.05
WIDTH, DEPTH = 10.0, 6.0
NOISE = 0.01
#: The room's free interior in world metres (2 wall cells around it).
X0, X1, Y0, Y1 = 2 * RES, 2 * RES + WIDTH, 2 * RES, 2 * RES + DEPTH


@pytest.fixture(scope="module")
def room() -> OccupancyGrid:
    rows, cols = round(DEPTH / RES) + 4, round(WIDTH / RES) + 4
    occ = np.zeros((rows, cols), dtype=bool)
    occ[:2, :] = occ[-2:, :] = occ[:, :2] = occ[:, -2:] = True
    return OccupancyGrid.from_masks(occ, RES)


def drive(room: OccupancyGrid, poses: np.ndarray, seed: int = 0) -> LocalMap:
    """A local map fed with noisy front scans from ``poses`` at 10 Hz."""
    rng = np.random.default_rng(seed)
    m = LocalMap()
    scans = cast(room, poses, n_beams=361, fov=math.pi, max_range=30.0, noise_std=NOISE, rng=rng)
    for k, (pose, r) in enumerate(zip(poses, scans, strict=True)):
        m.add(r, SICK, pose, stamp=0.1 * k, range_max=30.0)
    return m


def test_rear_beams_match_the_room_after_driving_forward(room: OccupancyGrid) -> None:
    # look around once (every wall seen), then drive 4 m forward along the room
    turn = [(2.0, 3.05, th) for th in np.linspace(0.0, 2 * math.pi, 60)]
    ahead = [(x, 3.05, 0.0) for x in np.arange(2.0, 6.0, 0.06)]
    poses = np.array(turn + ahead)
    m = drive(room, poses)
    pose = poses[-1]
    prm = FullScanParams()
    front = cast(room, pose, n_beams=361, fov=math.pi, max_range=30.0)
    full = full_scan(front, SICK, range_max=30.0, pose=pose, local_map=m, params=prm)
    truth = cast(room, pose, n_beams=360, max_range=30.0)
    rear = np.arange(91, 270)
    hits = simulate_rear(m.points, rear, prm, pose=pose)
    assert np.mean(~np.isnan(hits)) > 0.95  # nearly every rear beam hits a stored point

    # The error bound of one beam: a stored wall point may lie up to h_eff off the ray
    # (the hit radius, or half a beam step at that distance for far points); on a wall
    # met at incidence θ from its normal, its projection onto the ray is then up to
    # h_eff·tan θ from the true hit. Plus 4σ of the range noise the point was stored with.
    phi = output_angles(360)[rear] + pose[2]
    d = truth[rear].astype(np.float64)
    hx, hy = pose[0] + d * np.cos(phi), pose[1] + d * np.sin(phi)
    on_x_wall = (np.abs(hx - X0) < 0.02) | (np.abs(hx - X1) < 0.02)  # walls x = const
    incidence = np.where(on_x_wall, np.arccos(np.abs(np.cos(phi))), np.arccos(np.abs(np.sin(phi))))
    h_eff = np.maximum(prm.hit_radius, d * math.sin(0.5 * 2 * math.pi / 360))
    bound = 4 * NOISE + h_eff * np.tan(np.minimum(incidence, math.radians(80)))
    # a hit within a few centimetres of a corner may come from the other wall
    corner = (np.minimum(np.abs(hx - X0), np.abs(hx - X1)) < 0.3) & (
        np.minimum(np.abs(hy - Y0), np.abs(hy - Y1)) < 0.3
    )
    err = np.abs(full[rear] - truth[rear])
    assert (err[~corner] <= bound[~corner]).all(), np.max(err[~corner] - bound[~corner])
    assert np.median(err) < 0.05
    # the front half is the real scan, resampled
    front_out = np.r_[0:90, 271:360]
    assert np.allclose(full[front_out], truth[front_out], atol=1e-4)


def test_rear_beams_without_any_hit_are_interpolated_between_the_ends() -> None:
    prm = FullScanParams()
    front = np.full(361, 3.0)
    front[-1] = 2.0  # the beam at +90° (left)
    front[0] = 4.0  # the beam at -90° (right)
    full = full_scan(front, SICK, range_max=30.0, params=prm)
    # beams 90 (+90°) .. 270 (-90°): a straight line in the beam index from 2 m to 4 m
    assert full[90] == pytest.approx(2.0) and full[270] == pytest.approx(4.0)
    assert np.allclose(full[90:271], np.linspace(2.0, 4.0, 181), atol=1e-5)
    # an empty local map changes nothing
    assert np.array_equal(full, full_scan(front, SICK, range_max=30.0, pose=(0, 0, 0), local_map=LocalMap()))


def test_interpolation_across_a_gap_between_rear_hits() -> None:
    prm = FullScanParams()
    m = LocalMap()
    # a wall 2 m behind the robot, seen only on two stretches: rear beams 150-160 and 200-210
    xy = np.array([(-2.0, -2.0 * math.tan(math.radians(b))) for b in [*range(150, 161), *range(200, 211)]])
    m.add(np.hypot(*xy.T), np.arctan2(xy[:, 1], xy[:, 0]), (0.0, 0.0, 0.0), stamp=0.0, range_max=30.0)
    front = np.full(361, 5.0)
    full = full_scan(front, SICK, range_max=30.0, pose=(0.0, 0.0, 0.0), local_map=m, params=prm)
    known = np.ones(360, dtype=bool)
    known[91:270] = ~np.isnan(simulate_rear(m.points, np.arange(91, 270), prm))
    ranges, reported = assemble_scan(
        front, SICK, range_max=30.0, pose=(0.0, 0.0, 0.0), local_map=m, params=prm
    )
    assert np.array_equal(reported, known) and np.array_equal(ranges, full)
    assert known[150] and known[210] and not known[180] and not known[120]
    # every beam without a hit lies on the line between its nearest known neighbours
    for i in np.flatnonzero(~known):
        left = max(b for b in range(i) if known[b])
        right = min(b for b in range(i + 1, 360) if known[b])
        assert full[i] == pytest.approx(np.interp(i, [left, right], [full[left], full[right]]), abs=1e-5)
    # and the hits are the wall's ranges
    for b in (150, 155, 205, 210):
        assert full[b] == pytest.approx(2.0 / abs(math.cos(math.radians(b))), abs=0.08)


def test_a_360_degree_scan_is_only_resampled(room: OccupancyGrid) -> None:
    pose = np.array([3.0, 2.0, 0.4])
    prm = FullScanParams()
    scan = cast(room, pose, n_beams=360, max_range=30.0)
    m = LocalMap()
    m.add(np.full(361, 0.5), SICK, pose, stamp=0.0, range_max=30.0)  # would shorten every rear beam
    out = full_scan(scan, beam_angles(360), range_max=30.0, pose=pose, local_map=m, params=prm)
    assert np.array_equal(out, scan)
    # 720 beams at 0.5° → every other one
    fine = cast(room, pose, n_beams=720, max_range=30.0)
    out = full_scan(fine, beam_angles(720), range_max=30.0, params=prm)
    assert np.allclose(out, fine[::2])


def test_front_resampling_nearest_and_min() -> None:
    rng = np.random.default_rng(3)
    front = rng.uniform(1.0, 9.0, 361)
    nearest = resample(front, SICK, range_max=30.0, params=FullScanParams())[0]
    # SICK beam j sits at -90° + j/2 degrees: output beam i (i degrees) is beam 2i + 180 (mod)
    for i in [0, 1, 45, 89, 90, 270, 271, 359]:
        j = (2 * i + 180) % 720
        assert nearest[i] == pytest.approx(front[j])
    assert np.isnan(nearest[91:270]).all()
    lowest = resample(front, SICK, range_max=30.0, params=FullScanParams(front="min"))[0]
    # the sector of output beam i (width 1°) holds the beam at i° and half-step neighbours
    for i in [1, 45, 89, 271, 359]:
        j = (2 * i + 180) % 720
        assert lowest[i] == pytest.approx(min(front[j - 1 : j + 2]))


def test_no_return_is_max_range_and_invalid_beams_are_filled() -> None:
    prm = FullScanParams(max_range=30.0)
    front = np.full(361, 2.0)
    front[180] = 8.0  # a SICK in 8 m mode: nothing within range straight ahead
    front[100:104] = 0.0  # dazzled: below range_min
    front[300] = np.nan
    out = full_scan(front, SICK, range_max=8.0, range_min=0.05, params=prm)
    assert out[0] == pytest.approx(30.0)
    # the invalid readings are filled from their neighbours (2 m on both sides)
    assert np.allclose(out[np.r_[1:90, 271:360]], 2.0)
    assert out.dtype == np.float32 and out.shape == (360,)
    assert (out >= 0).all() and (out <= 30.0).all()


def test_checks() -> None:
    with pytest.raises(ValueError, match="front"):
        FullScanParams(front="mean")
    with pytest.raises(ValueError, match="n_beams"):
        FullScanParams(n_beams=2)
    with pytest.raises(ValueError, match="same length"):
        full_scan(np.ones(10), np.ones(11), range_max=8.0)
    m = LocalMap()
    m.add(np.ones(361), SICK, (0.0, 0.0, 0.0), stamp=0.0, range_max=8.0)
    with pytest.raises(ValueError, match="pose"):
        full_scan(np.ones(361), SICK, range_max=8.0, local_map=m)
