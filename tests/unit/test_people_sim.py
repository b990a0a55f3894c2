"""Simulated people: the gait, the speed, paths in a world, and the bundled detector on virtual-LMS scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from knowledge.metric.grid import OccupancyGrid
from knowledge.people.detector import LegDetector
from knowledge.people.pipeline import PeoplePipeline
from sim.lms_world import Leg, LmsWorld
from sim.people import Gait, SimPerson, clear_path, legs_of, walkers_in

N_BEAMS = 768
INC = 0.006135923322290182
ANGLE_MIN = -2.356194496154785
FOV = INC * (N_BEAMS - 1)
RMAX = 11.0


def room() -> OccupancyGrid:
    occ = np.zeros((200, 200), dtype=bool)  # 10 m × 10 m at 5 cm
    occ[:3] = occ[-3:] = True
    occ[:, :3] = occ[:, -3:] = True
    occ[40:50, 120:126] = True  # a pillar
    return OccupancyGrid.from_masks(occ, 0.05)


def along(person: SimPerson, t: float) -> np.ndarray:
    """Offsets of the two legs from the body along the walking direction, metres."""
    x, y, h = person.body(t)
    legs = person.leg_positions(t)
    return (legs[:, 0] - x) * math.cos(h) + (legs[:, 1] - y) * math.sin(h)


def test_legs_alternate_with_a_gait() -> None:
    p = SimPerson([(0.0, 0.0), (50.0, 0.0)], speed=1.2)
    ts = np.arange(0.0, 10.0, 0.01)
    off = np.array([along(p, t) for t in ts])
    # antiphase: when one leg is ahead the other is behind
    assert np.corrcoef(off[:, 0], off[:, 1])[0, 1] < -0.8
    # each leg swings forward once per stride: 10 s × 1.2 m/s / 1.2 m = 10 cycles
    forward = int(((off[:-1, 0] < 0) & (off[1:, 0] >= 0)).sum())
    assert forward == 10
    # during stance the foot is planted: at the scan height the leg moves at speed·h/H only
    g = p.gait
    legs = np.array([p.leg_positions(t) for t in ts])
    v = np.hypot(*np.diff(legs[:, 0], axis=0).T) / 0.01
    stance = np.array([g.in_stance(p.leg_phases(t)[0]) for t in ts[:-1]])
    assert np.median(v[stance]) == pytest.approx(1.2 * g.scan_height / g.hip_height, rel=0.05)
    assert np.median(v[~stance]) > 1.2 * 1.5
    # with a stance fraction above one half, both legs are never in swing together
    both_swing = [not g.in_stance(a) and not g.in_stance(b) for a, b in (p.leg_phases(t) for t in ts)]
    assert not any(both_swing)
    # the legs stand stance_width apart across the walking direction
    np.testing.assert_allclose(np.abs(legs[:, :, 1]), g.stance_width / 2, atol=1e-9)


@pytest.mark.parametrize("speed", [0.5, 1.0, 1.6])
def test_moves_at_the_configured_speed(speed: float) -> None:
    p = SimPerson([(0.0, 0.0), (3.0, 4.0), (3.0, 20.0)], speed=speed, mode="stop")
    x0 = np.mean(p.leg_positions(2.0), axis=0)
    x1 = np.mean(p.leg_positions(6.0), axis=0)
    body = np.array([p.position(t) for t in np.arange(2.0, 6.0 + 1e-9, 0.05)])
    walked = np.hypot(*np.diff(body, axis=0).T).sum()
    assert walked == pytest.approx(4.0 * speed, rel=1e-3)  # sampled: cuts the corner a little
    # the legs' midpoint keeps up with the body within a step
    assert np.linalg.norm(x1 - x0) == pytest.approx(
        np.linalg.norm(np.subtract(p.position(6.0), p.position(2.0))), abs=0.35
    )
    vx, vy = p.velocity(1.0)
    assert math.hypot(vx, vy) == pytest.approx(speed)
    assert math.atan2(vy, vx) == pytest.approx(math.atan2(4.0, 3.0))
    # at the end of the path it stands still, legs together
    t_end = p.length / speed + 1.0
    assert p.velocity(t_end) == (0.0, 0.0)
    assert not p.walking(t_end)
    np.testing.assert_allclose(np.mean(p.leg_positions(t_end), axis=0), (3.0, 20.0))


def test_path_modes_and_standing() -> None:
    pp = SimPerson([(0.0, 0.0), (2.0, 0.0)], speed=1.0, mode="pingpong")
    assert pp.position(3.0) == pytest.approx((1.0, 0.0))  # on its way back
    assert pp.velocity(3.0)[0] == pytest.approx(-1.0)
    loop = SimPerson([(0.0, 0.0), (2.0, 0.0), (2.0, 2.0)], speed=1.0, mode="loop")
    assert loop.length == pytest.approx(4.0 + math.hypot(2.0, 2.0))
    assert loop.position(loop.length + 0.5) == pytest.approx((0.5, 0.0))
    stand = SimPerson([(1.0, 1.0)], speed=0.0)
    legs = stand.leg_positions(5.0)
    assert np.linalg.norm(legs[0] - legs[1]) == pytest.approx(stand.gait.stance_width)
    with pytest.raises(ValueError, match="two distinct waypoints"):
        SimPerson([(0.0, 0.0)], speed=1.0)
    with pytest.raises(ValueError, match="mode"):
        SimPerson([(0.0, 0.0), (1.0, 0.0)], mode="wander")
    with pytest.raises(ValueError, match="stance_fraction"):
        Gait(stance_fraction=1.5)


def test_walkers_stay_in_free_space() -> None:
    grid = room()
    people = walkers_in(grid, (5.0, 5.0), 4, seed=3)
    assert len(people) == 4
    for p in people:
        for a, b in zip(p.waypoints[:-1], p.waypoints[1:], strict=True):
            assert clear_path(grid, tuple(a), tuple(b), 0.3)
    assert not clear_path(grid, (5.0, 5.0), (6.2, 8.0), 0.3)  # through the pillar
    assert len(legs_of(people)) == 8


def test_bundled_detector_finds_simulated_people_in_virtual_lms_scans() -> None:
    """Ray-cast room + leg circles, 768 beams over 270° like the legs data; measures the rate."""
    grid = room()
    pose = (5.0, 5.0, 0.0)
    people = [
        SimPerson([(6.0, 3.0), (8.5, 6.5)], 1.0),
        SimPerson([(3.0, 7.0), (7.0, 8.0)], 0.8, phase=0.3),
    ]
    world = LmsWorld(grid, pose, legs_of(people), noise_std=0.01, seed=0)
    pipe = PeoplePipeline(LegDetector.load())
    n_scans, period = 60, 1 / 7.5
    found_legs = false_legs = people_found = 0
    for i in range(n_scans):
        t = i * period
        r = world.ranges(t, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
        frame = pipe.process(r, t, angle_min=ANGLE_MIN, angle_increment=INC, range_max=RMAX, sensor_pose=pose)
        truth = np.vstack([p.leg_positions(t) for p in people])
        if len(frame.legs):
            D = np.hypot(
                frame.legs[:, None, 0] - truth[None, :, 0], frame.legs[:, None, 1] - truth[None, :, 1]
            )
            found_legs += int((D < 0.2).any(axis=0).sum())
            false_legs += int((D.min(axis=1) > 0.3).sum())
        if len(frame.people):
            P = frame.people.positions
            for p in people:
                if np.hypot(*(P - np.array(p.position(t))).T).min() < 0.3:
                    people_found += 1
    leg_recall = found_legs / (len(truth) * n_scans)
    person_rate = people_found / (len(people) * n_scans)
    false_per_scan = false_legs / n_scans
    print(
        f"sim: leg recall {leg_recall:.2f}, people found {person_rate:.2f}, false legs/scan {false_per_scan:.2f}"
    )
    assert leg_recall >= 0.6
    assert person_rate >= 0.75
    assert false_per_scan <= 1.0
    # and the tracker followed both for the last scans
    assert len(frame.tracks) >= 2


def test_pipeline_takes_range_min_from_the_laser_scan() -> None:
    """Error codes below the scan's range_min (a Hokuyo's few millimetres) are no returns."""
    from drivers.messages import LaserScan

    grid = room()
    pose = (5.0, 5.0, 0.0)
    people = [SimPerson([(7.0, 5.0), (7.0, 5.01)], 0.0)]
    world = LmsWorld(grid, pose, legs_of(people), noise_std=0.0, seed=0)
    r = world.ranges(0.0, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
    clean = PeoplePipeline(LegDetector.load()).process(
        r, 0.0, angle_min=ANGLE_MIN, angle_increment=INC, range_max=RMAX
    )
    assert len(clean.legs) >= 1
    dirty = r.copy()
    for seg in np.flatnonzero(clean.detection.is_person):
        beams = clean.detection.segmentation.segment_beams(int(seg))
        dirty[beams[::3]] = 0.007  # every third beam of each leg is an error code
    scan = LaserScan(0.0, 0, "laser", ANGLE_MIN, INC, RMAX, dirty.astype(np.float32), range_min=0.02)
    frame = PeoplePipeline(LegDetector.load()).process_scan(scan)
    assert frame.legs.shape == clean.legs.shape
    np.testing.assert_allclose(frame.legs, clean.legs, atol=0.02)
    # the same scan without its range_min: the codes are points at the laser, the legs are cut up
    raw = PeoplePipeline(LegDetector.load()).process(
        dirty, 0.0, angle_min=ANGLE_MIN, angle_increment=INC, range_max=RMAX
    )
    assert raw.detection.segmentation.n_segments > frame.detection.segmentation.n_segments


def furniture_and_a_walker(pipe: PeoplePipeline) -> tuple[int, int, bool]:
    """A laser driven at 0.8 m/s down a 10 m room past a four-legged stool and two table
    legs (circles of a leg's size that never move), while a person walks across ahead of it.
    Returns (confirmed tracks that sat on the furniture, scans with such a track, whether the
    walker had a confirmed track)."""
    grid = room()
    furniture = [(6.0, 3.2), (6.25, 3.2), (6.0, 3.45), (6.25, 3.45), (7.5, 7.0), (8.6, 7.1)]
    walker = SimPerson([(4.5, 8.5), (5.5, 1.5)], 0.9)

    def pose(t: float) -> tuple[float, float, float]:
        return (1.0 + 0.8 * t, 5.0, 0.0)

    legs = [Leg(p) for p in furniture] + list(walker.legs())
    world = LmsWorld(grid, pose, legs, noise_std=0.01, seed=1)
    on_furniture: set[int] = set()
    scans_with = 0
    walker_tracked = False
    F = np.array(furniture)
    for i in range(int(6.0 * 7.5)):
        t = i / 7.5
        r = world.ranges(t, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
        frame = pipe.process(
            r, t, angle_min=ANGLE_MIN, angle_increment=INC, range_max=RMAX, sensor_pose=pose(t)
        )
        bad = False
        for tr in frame.tracks:
            if np.hypot(*(F - tr.position).T).min() < 0.3:
                on_furniture.add(tr.id)
                bad = True
            if math.dist(tr.position, walker.position(t)) < 0.4:
                walker_tracked = True
        scans_with += bad
    return len(on_furniture), scans_with, walker_tracked


def test_furniture_that_looks_like_legs_starts_no_track_and_a_walker_does() -> None:
    from knowledge.people.tracking import TrackerConfig

    det = LegDetector.load()
    n, scans, walker = furniture_and_a_walker(PeoplePipeline(det))
    n0, scans0, walker0 = furniture_and_a_walker(
        PeoplePipeline(det, tracker=TrackerConfig(), static=None, min_seen_through=0, min_score=None)
    )
    print(f"furniture tracks: plain tracker {n0} in {scans0} scans, with evidence {n} in {scans}")
    assert walker and walker0
    assert n0 >= 1  # the plain tracker takes the stool's legs for people
    assert n == 0


def test_min_score_drops_weak_legs_as_a_higher_detector_threshold_would() -> None:
    """PeoplePipeline(min_score=s) keeps the segments with F >= s: the same legs, people and
    tracks as a detector whose threshold is s, and its frame's detection marks only them."""
    import copy

    grid = room()
    people = [SimPerson([(6.0, 3.0), (8.5, 6.5)], 1.0), SimPerson([(3.0, 7.0), (7.0, 8.0)], 0.8, phase=0.3)]
    world = LmsWorld(grid, (5.0, 5.0, 0.0), legs_of(people), noise_std=0.01, seed=0)
    det = LegDetector.load()
    strict = copy.copy(det)
    strict.threshold = 0.6
    a, b, c = PeoplePipeline(det, min_score=0.6), PeoplePipeline(strict), PeoplePipeline(det)
    dropped = 0
    for i in range(30):
        t = i / 7.5
        r = world.ranges(t, n_beams=N_BEAMS, fov=FOV, max_range=RMAX, angle_min=ANGLE_MIN)
        kw = {
            "angle_min": ANGLE_MIN,
            "angle_increment": INC,
            "range_max": RMAX,
            "sensor_pose": (5.0, 5.0, 0.0),
        }
        fa, fb, fc = a.process(r, t, **kw), b.process(r, t, **kw), c.process(r, t, **kw)
        assert np.array_equal(fa.legs, fb.legs) and np.array_equal(
            fa.detection.is_person, fb.detection.is_person
        )
        assert np.array_equal(fa.people.positions, fb.people.positions)
        assert [(x.id, *x.position) for x in fa.tracks] == [(x.id, *x.position) for x in fb.tracks]
        assert (fa.detection.score[fa.detection.is_person] >= 0.6).all()
        dropped += len(fc.legs) - len(fa.legs)
    assert dropped > 0  # some legs scored between 0 and 0.6: the option did something
    with pytest.raises(ValueError, match="min_score"):
        PeoplePipeline(det, min_score=float("nan"))
