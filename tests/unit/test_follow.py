"""Follow me: target choice, keeping the target, goals 1 m short of the person, lost and reacquired;
and the closed loop SimRobot laser → PeoplePipeline (bundled detector) → FollowMe → goals → SimRobot."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.follow import (
    LOST_MESSAGE,
    NOBODY_MESSAGE,
    FollowMe,
    FollowParams,
    FollowStep,
    goal_behind,
)
from knowledge.people.tracking import TrackState

ORIGIN = (0.0, 0.0, 0.0)


def track(
    tid: int,
    x: float,
    y: float,
    vx: float = 0.0,
    vy: float = 0.0,
    *,
    misses: int = 0,
    first_seen: float = 0.0,
    last_seen: float = 0.0,
) -> TrackState:
    return TrackState(
        id=tid,
        position=np.array([x, y]),
        velocity=np.array([vx, vy]),
        covariance=np.eye(4) * 0.01,
        hits=5,
        misses=misses,
        age=5 + misses,
        first_seen=first_seen,
        last_seen=last_seen,
    )


def started(t: float = 0.0, **kw: float) -> FollowMe:
    f = FollowMe(FollowParams(**kw))
    f.start(t)
    return f


def expected_goal(person: Sequence[float], robot: Sequence[float], d: float = 1.0) -> tuple[float, float]:
    """The point ``d`` metres from the person towards the robot (written out independently)."""
    px, py = person
    rx, ry = robot[0], robot[1]
    ang = math.atan2(ry - py, rx - px)
    return (px + d * math.cos(ang), py + d * math.sin(ang))


# ---------------------------------------------------------------------------- choosing the target
def test_picks_the_nearest_person_in_front_not_one_behind_or_aside() -> None:
    f = started()
    tracks = [
        track(1, 2.5, 0.0),  # straight ahead, 2.5 m
        track(2, 1.5, 1.0),  # 34° left, 1.8 m: the one
        track(3, -1.0, 0.0),  # behind, nearer
        track(4, 0.5, 1.5),  # 72° left (outside ±60°), nearer
        track(5, 1.2, 0.2, misses=2),  # nearest in front, but not seen in this scan
    ]
    step = f.update(tracks, ORIGIN, 0.1)
    assert step.state == "following"
    assert step.target_track == 2
    assert step.goal is not None
    gx, gy = expected_goal((1.5, 1.0), ORIGIN)
    assert step.goal[0] == pytest.approx(gx)
    assert step.goal[1] == pytest.approx(gy)
    assert step.goal[2] == pytest.approx(math.atan2(1.0, 1.5))  # facing the person
    assert step.message is None and not step.cancel


def test_the_cone_and_the_range_follow_the_robots_heading() -> None:
    robot = (5.0, 5.0, math.pi / 2)  # facing +y
    f = started()
    ahead_of_x = [track(1, 6.5, 5.0), track(2, 5.0, 7.5)]  # +x is 90° to its right; +y ahead
    assert f.update(ahead_of_x, robot, 0.1).target_track == 2
    far = started(max_range=3.0)
    assert far.update([track(7, 5.0, 8.2)], robot, 0.1).state == "searching"  # 3.2 m away


def test_a_person_behind_the_robot_is_ignored_until_search_gives_up() -> None:
    f = started(0.0, search_for=3.0)
    behind = [track(1, -1.2, 0.1)]
    for t in np.arange(0.1, 3.0, 0.1):
        step = f.update(behind, ORIGIN, float(t))
        assert step == FollowStep(None, "searching", None)
        assert f.active
    step = f.update(behind, ORIGIN, 3.0)
    assert step.state == "lost" and step.message == NOBODY_MESSAGE and step.cancel
    assert not f.active


def test_a_person_appearing_in_front_while_searching_is_taken() -> None:
    f = started()
    assert f.update([], ORIGIN, 0.1).state == "searching"
    step = f.update([track(9, 2.0, -0.5)], ORIGIN, 0.2)
    assert (step.state, step.target_track) == ("following", 9)


# ---------------------------------------------------------------------------- keeping the target
def test_keeps_its_target_when_someone_nearer_walks_past() -> None:
    f = started()
    goals = []
    for k in range(1, 60):
        t = 0.1 * k
        target = track(1, 2.0 + 0.5 * t, 0.0, 0.5, 0.0)
        passer = track(2, 5.0 - 1.2 * t, 0.4, -1.2, 0.0, first_seen=0.0)  # passes between robot and target
        step = f.update([passer, target] if k > 1 else [target], ORIGIN, t)
        assert step.state == "following"
        assert step.target_track == 1
        if step.goal is not None:
            goals.append((t, step.goal))
    assert len(goals) >= 3
    for t, (gx, gy, _) in goals:
        ex, ey = expected_goal((2.0 + 0.5 * t, 0.0), ORIGIN)
        assert (gx, gy) == pytest.approx((ex, ey))


def test_no_new_goal_for_jitter_below_the_tolerance() -> None:
    f = started(tolerance=0.25)
    rng = np.random.default_rng(3)
    first = f.update([track(1, 3.0, 0.0)], ORIGIN, 0.1)
    assert first.goal is not None
    robot = (first.goal[0], first.goal[1], first.goal[2])  # it drove there
    for k in range(2, 40):
        dx, dy = rng.normal(0.0, 0.04, 2)
        step = f.update([track(1, 3.0 + dx, dy)], robot, 0.1 * k)
        assert step.goal is None and step.state == "following"
    moved = f.update([track(1, 3.4, 0.0)], robot, 4.0)
    assert moved.goal is not None
    assert moved.goal[:2] == pytest.approx(expected_goal((3.4, 0.0), robot))


def test_a_lagging_robot_gets_a_new_goal_per_tolerance_not_per_scan() -> None:
    f = started(tolerance=0.15)
    f.update([track(1, 3.0, 0.0)], ORIGIN, 0.0)
    goals = [f.update([track(1, 3.0 + 0.06 * k, 0.0)], ORIGIN, 0.1 * k).goal for k in range(1, 21)]
    sent = [k for k, g in enumerate(goals, 1) if g is not None]
    assert sent == [
        3,
        6,
        9,
        12,
        15,
        18,
    ]  # every 0.18 m walked, although the robot is further behind all along


def test_a_person_already_close_gives_a_turn_in_place() -> None:
    f = started()
    robot = (1.0, 2.0, 0.0)
    step = f.update([track(1, 1.3, 2.5)], robot, 0.1)  # 0.58 m away, 59° left
    assert step.goal is not None
    assert step.goal[:2] == pytest.approx(robot[:2])
    assert step.goal[2] == pytest.approx(math.atan2(0.5, 0.3))


# ---------------------------------------------------------------------------- lost and reacquired
def test_lost_after_the_timeout_says_so_once_and_stays_lost() -> None:
    f = started(lost_after=2.0, chase_for=1.5)
    for k in range(1, 11):
        f.update([track(1, 2.0, 0.0)], ORIGIN, 0.1 * k)  # last seen at t = 1.0
    # vanished: once, go and look where they were last seen (chase_short = 0.5 m short of it)
    step = f.update([], ORIGIN, 1.1)
    assert (step.state, step.target_track, step.message) == ("following", 1, None)
    assert step.goal == pytest.approx((1.5, 0.0, 0.0))
    # the chase gets chase_for seconds beyond lost_after: 2 + 1.5 s after last seen
    for t in np.arange(1.2, 4.45, 0.1):
        step = f.update([], ORIGIN, float(t))
        assert (step.state, step.target_track, step.goal, step.message) == ("following", 1, None, None)
    step = f.update([], ORIGIN, 4.5)
    assert step == FollowStep(None, "lost", 1, LOST_MESSAGE, cancel=True)
    later = [f.update([track(1, 2.0, 0.0)], ORIGIN, 4.5 + 0.1 * k) for k in range(1, 20)]
    assert all(s == FollowStep(None, "lost", None) for s in later)  # once, no goals, not resumed
    f.start(7.0)
    assert f.update([track(1, 2.0, 0.0)], ORIGIN, 7.1).state == "following"


def test_a_track_that_vanishes_late_is_still_chased() -> None:
    """The track coasted (hidden) until just before lost_after, then vanished: the robot still
    drives to where the person was last seen, and has chase_for seconds to get there."""
    f = started(lost_after=2.0, chase_for=4.0)
    f.update([track(1, 2.0, 0.0)], ORIGIN, 0.0)
    assert f.update([track(1, 2.1, 0.0, misses=30)], ORIGIN, 1.9).state == "following"
    step = f.update([], ORIGIN, 2.1)  # past lost_after, the track gone: chase, not lost
    # to 0.5 m short of where the person was last seen (not where the coasting track drifted:
    # in the noisy-odometry tour such a prediction went 4 m on, through the walls)
    assert step.state == "following" and step.goal == pytest.approx((1.5, 0.0, 0.0))
    assert f.update([], ORIGIN, 5.9).state == "following"
    assert f.update([], ORIGIN, 6.0).message == LOST_MESSAGE


def test_a_coasting_track_does_not_keep_the_target_alive_forever() -> None:
    f = started(lost_after=2.0)
    f.update([track(1, 2.0, 0.0)], ORIGIN, 0.0)
    steps = [f.update([track(1, 2.0, 0.0, misses=k)], ORIGIN, 0.5 * k) for k in range(1, 5)]
    assert [s.state for s in steps] == ["following", "following", "following", "lost"]
    assert steps[-1].message == LOST_MESSAGE


def test_reacquires_a_new_track_near_the_predicted_position() -> None:
    f = started()
    for k in range(11):
        t = 0.1 * k
        f.update([track(1, 2.0 + 0.5 * t, 0.0, 0.5, 0.0)], ORIGIN, t)  # last seen at (2.5, 0), t = 1.0
    old_neighbour = track(3, 2.9, 0.2, first_seen=0.2)  # near the prediction but older: someone else
    decoy = track(6, 1.5, 0.3, first_seen=1.2)  # new and nearer the robot, far from the prediction
    assert f.update([old_neighbour, decoy], ORIGIN, 1.5).target_track == 1
    step = f.update([old_neighbour, decoy, track(5, 2.85, -0.1, first_seen=1.3)], ORIGIN, 1.6)
    assert (step.state, step.target_track) == ("following", 5)  # predicted (2.8, 0)
    step = f.update([track(5, 3.0, 0.0)], ORIGIN, 4.0)
    assert step.state == "following"  # seen again: the lost clock restarted


def test_the_same_person_tracked_twice_keeps_being_followed_when_the_target_track_dies() -> None:
    """The tutor's legs tracked apart: track 1 (the target) dies, track 2, as old, lived
    beside it and takes over; someone who was 2 m from the target then does not."""
    f = started()
    for k in range(11):
        t = 0.1 * k
        f.update(
            [track(1, 2.0, 0.0), track(2, 2.3, 0.4, first_seen=0.0), track(3, 2.0, 2.2, first_seen=0.0)],
            ORIGIN,
            t,
        )
    # track 1 gone; the other two stay where they were, track 3 now nearer the prediction
    step = f.update([track(3, 2.2, 0.9, first_seen=0.0), track(2, 2.3, 0.5, first_seen=0.0)], ORIGIN, 1.1)
    assert (step.state, step.target_track) == ("following", 2)
    f = started(sibling_radius=0.0)  # without: only tracks born since may take over
    for k in range(11):
        f.update([track(1, 2.0, 0.0), track(2, 2.3, 0.4, first_seen=0.0)], ORIGIN, 0.1 * k)
    assert f.update([track(2, 2.3, 0.5, first_seen=0.0)], ORIGIN, 1.1).target_track == 1  # still the lost one


def test_a_person_seen_takes_over_from_the_targets_track_coasting_through_the_walls() -> None:
    """The target's track coasts on its prediction (the tracker lost the legs); the tutor's
    legs are now another, older track, which was itself coasting when the target was last
    seen: the robot follows it at once, not the prediction. A person seen 2 m from the target
    at that time (someone else) is not taken."""
    f = started()
    for k in range(11):
        t = 0.1 * k
        f.update(
            [track(1, 2.0, 0.0, 0.0, 1.0), track(3, 2.6, 0.9, first_seen=0.0, misses=7), track(4, 4.0, 0.0)],
            ORIGIN,
            t,
        )
    coasting = track(1, 2.0, 2.5, 0.0, 1.0, misses=40)  # drifting off at 1 m/s
    stranger = track(4, 2.5, 0.6, first_seen=0.0)  # seen 2 m away before: not the tutor
    assert f.update([coasting, stranger], ORIGIN, 1.2).target_track == 1
    # a short occlusion (under coast_takeover, 0.5 s) keeps the target even with the tutor seen
    assert f.update([coasting, stranger, track(3, 2.2, 0.4, first_seen=0.0)], ORIGIN, 1.3).target_track == 1
    step = f.update([coasting, stranger, track(3, 2.2, 0.7, first_seen=0.0)], ORIGIN, 1.6)
    assert (step.state, step.target_track) == ("following", 3)
    assert step.goal is not None and math.hypot(step.goal[0] - 2.2, step.goal[1] - 0.7) == pytest.approx(1.0)


def test_the_reacquisition_radius_grows_while_the_target_is_unseen() -> None:
    """A person who turned a corner reappears farther from the prediction the longer it took."""
    f = started(lost_after=3.0, reacquire_radius=0.8, search_speed=0.6, max_prediction=0.0)
    f.update([track(1, 2.0, 0.0)], ORIGIN, 1.0)  # last seen at (2, 0), t = 1.0
    early = track(2, 2.0, 1.3, first_seen=1.1)  # 1.3 m away, 0.2 s later: radius 0.92 m
    assert f.update([early], ORIGIN, 1.2).target_track == 1
    late = track(3, 2.0, 1.3, first_seen=2.4)  # the same place, 1.5 s later: radius 1.7 m
    assert f.update([late], ORIGIN, 2.5).target_track == 3


def test_a_new_track_far_from_the_prediction_is_not_the_target() -> None:
    f = started(lost_after=1.0, chase_for=0.0)
    f.update([track(1, 2.0, 0.0)], ORIGIN, 0.0)
    stranger = track(2, 2.0, 1.5, first_seen=0.5)
    assert f.update([stranger], ORIGIN, 0.9).target_track == 1
    assert f.update([stranger], ORIGIN, 1.0).state == "lost"


def test_the_search_radius_stops_growing() -> None:
    f = started(lost_after=2.0, chase_for=6.0, reacquire_radius=0.8, search_speed=0.6, max_search_radius=2.0)
    f.update([track(1, 2.0, 0.0)], ORIGIN, 0.0)
    far = track(2, 2.0, 2.2, first_seen=5.0)  # 2.2 m from where the target was last seen
    assert f.update([far], ORIGIN, 5.0).target_track == 1  # 0.8 + 3 m, capped at 2 m
    near = track(3, 2.0, 1.9, first_seen=5.1)
    assert f.update([far, near], ORIGIN, 5.1).target_track == 3


# ---------------------------------------------------------------------------- contract details
def test_idle_before_start_and_after_stop() -> None:
    f = FollowMe()
    assert not f.active
    assert f.update([track(1, 2.0, 0.0)], ORIGIN, 0.0) == FollowStep(None, "idle", None)
    f.start(0.0)
    assert f.update([track(1, 2.0, 0.0)], ORIGIN, 0.1).state == "following"
    f.stop()
    assert not f.active and f.target is None
    assert f.update([track(1, 2.0, 0.0)], ORIGIN, 0.2) == FollowStep(None, "idle", None)


def test_rejects_time_going_backwards_and_non_finite_input() -> None:
    f = started()
    f.update([], ORIGIN, 1.0)
    with pytest.raises(ValueError, match="backwards"):
        f.update([], ORIGIN, 0.5)
    with pytest.raises(ValueError, match="finite"):
        f.update([], (math.nan, 0.0, 0.0), 2.0)
    with pytest.raises(ValueError, match="finite"):
        f.start(math.inf)


@pytest.mark.parametrize(
    ("kw", "name"),
    [
        ({"distance": 0.0}, "distance"),
        ({"lost_after": -1.0}, "lost_after"),
        ({"max_range": math.nan}, "max_range"),
        ({"cone": 0.0}, "cone"),
        ({"cone": 60.0}, "cone"),  # degrees by mistake
        ({"tolerance": -0.1}, "tolerance"),
        ({"heading_tolerance": math.inf}, "heading_tolerance"),
        ({"reacquire_radius": 0.0}, "reacquire_radius"),
        ({"max_prediction": -1.0}, "max_prediction"),
        ({"search_for": 0.0}, "search_for"),
    ],
)
def test_params_are_validated(kw: dict[str, float], name: str) -> None:
    with pytest.raises(ValueError, match=f"FollowParams.{name}"):
        FollowParams(**kw)


finite = st.floats(-20.0, 20.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(finite, finite, st.floats(-math.pi, math.pi), finite, finite, st.floats(0.3, 2.0))
def test_goal_is_distance_short_of_the_person_facing_them(
    rx: float, ry: float, rth: float, px: float, py: float, d: float
) -> None:
    n = math.hypot(px - rx, py - ry)
    gx, gy, gth = goal_behind((px, py), (rx, ry, rth), d)
    if n <= d:
        assert (gx, gy) == (rx, ry)  # never backs away from the person
    else:
        assert math.hypot(px - gx, py - gy) == pytest.approx(d, abs=1e-9)
        assert math.hypot(gx - rx, gy - ry) == pytest.approx(n - d, abs=1e-9)  # on the segment
    if n > 1e-6:
        assert math.cos(gth - math.atan2(py - ry, px - rx)) == pytest.approx(1.0, abs=1e-9)


# ---------------------------------------------------------------------------- closed loop in the simulator
BEAMS = 720  # the 360° laser at 0.5°, cut to its front half: a SICK LMS 2xx at 0.5° (361 beams)
START = (13.575, 24.125, 0.0)  # gen:1's corridor axis, facing +x


def front_half(ranges: np.ndarray) -> np.ndarray:
    """Beams −90° … +90° of a 360° scan whose beam ``i`` is at ``i·2π/n``."""
    q = ranges.size // 4
    return np.concatenate([ranges[-q:], ranges[: q + 1]])


@pytest.mark.slow
def test_closed_loop_follows_a_walker_down_a_corridor_and_loses_them_through_a_door() -> None:
    """SimRobot (front laser, noisy odometry) → PeoplePipeline (the bundled model) → FollowMe →
    goals in the odometry frame → SimRobot, in the generated building gen:1.

    The person starts 1.7 m ahead, walks 3.7 m along the corridor at 0.5 m/s, stands for 6 s,
    then walks at 1.3 m/s through a door into an office and along its wall, out of the
    laser's sight. Another person walks the other way, passing 0.63 m from the target.
    """
    from drivers.messages import LaserScan
    from knowledge.people.pipeline import PeoplePipeline
    from sim.lms_world import Leg, ray_circle_ranges
    from sim.people import SimPerson
    from sim.robot import Goal, SimRobot, SimRobotConfig

    cfg = SimRobotConfig(
        world="gen:1", start=START, laser="360", beams=BEAMS, scan_rate=25.0, scan_range=10.0
    )
    robot = SimRobot(cfg)
    walk = SimPerson([(15.3, 24.125), (19.0, 24.125)], speed=0.5, mode="stop")
    t_stand = walk.length / walk.speed
    t_leave = t_stand + 6.0
    leave = SimPerson(
        [(19.0, 24.125), (19.05, 25.0), (19.05, 27.2), (15.3, 27.2), (15.2, 26.1)],
        speed=1.3,
        mode="stop",
        start_time=t_leave,
    )
    passer = SimPerson([(22.0, 23.5), (11.0, 23.5)], speed=0.8, mode="stop", start_time=2.0)

    def person(t: float) -> SimPerson:
        return leave if t >= t_leave else walk

    def leg(k: int) -> Leg:
        def at(t: float) -> tuple[float, float]:
            x, y = person(t).leg_positions(t)[k]
            return (float(x), float(y))

        return Leg(at)

    robot.legs = [leg(0), leg(1)]  # the walker, then the same person leaving
    robot.legs += list(passer.legs())
    scans: list[LaserScan] = []
    robot.scan_listeners.append(scans.append)
    pipe = PeoplePipeline()
    follow = FollowMe(FollowParams(distance=1.0, lost_after=2.0))
    follow.start(robot.step().stamp)

    dist: list[tuple[float, float]] = []  # (time, robot ↔ person metres), every step
    visible_until = 0.0  # the last time ≥ 2 beams within 5 m hit the person's legs
    wrong_target = 0
    messages: list[tuple[float, str]] = []
    goals_after_lost = 0
    lost_at: float | None = None
    n_goals = goals_standing = 0
    for _ in range(round((t_leave + 9.0) * cfg.odom_rate)):
        sample = robot.step()
        t = robot.base.time
        truth = sample.truth
        body = person(t).position(t)
        dist.append((t, math.hypot(body[0] - truth.x, body[1] - truth.y)))
        while scans:
            scan = scans.pop(0)
            r = front_half(scan.ranges)
            beams = truth.theta - math.pi / 2 + scan.angle_increment * np.arange(r.size)
            legs = ray_circle_ranges((truth.x, truth.y), beams, person(t).leg_positions(t), np.full(2, 0.06))
            if int(((np.abs(r - legs) < 0.05) & (legs < 5.0)).sum()) >= 2:
                visible_until = t
            odom = (sample.odom.x, sample.odom.y, sample.odom.theta)
            frame = pipe.process(
                r,
                scan.stamp,
                angle_min=-math.pi / 2,
                angle_increment=scan.angle_increment,
                range_max=scan.range_max,
                sensor_pose=cfg.mount.apply(odom),
            )
            step = follow.update(frame, odom, scan.stamp)
            if step.state == "following" and t < t_leave:
                # the target is the walker (not the passer): its track is where the odometry
                # says the walker is (the true position seen through the odometry's drift)
                tr = {s.id: s for s in frame.tracks}.get(step.target_track or -1)
                if tr is not None:
                    dx, dy = body[0] - truth.x, body[1] - truth.y
                    c, s_ = math.cos(odom[2] - truth.theta), math.sin(odom[2] - truth.theta)
                    seen = (odom[0] + c * dx - s_ * dy, odom[1] + s_ * dx + c * dy)
                    wrong_target += math.dist(seen, tr.position) > 0.5
            if step.message:
                messages.append((t, step.message))
            if step.cancel:
                robot.cancel()
                lost_at = t
            if step.goal is not None:
                goals_after_lost += lost_at is not None
                goals_standing += t_stand + 3.0 < t < t_leave
                n_goals += 1
                robot.send_goal(Goal(f"follow-{n_goals}", (step.goal[:2],), heading=step.goal[2]))

    D = np.array(dist)
    walking = (D[:, 0] > 2.0) & (D[:, 0] < t_stand)
    standing = (D[:, 0] > t_stand + 3.0) & (D[:, 0] < t_leave)
    err_walk, err_stand = np.abs(D[walking, 1] - 1.0), np.abs(D[standing, 1] - 1.0)
    print(
        f"following error |d − 1 m|: walking mean {err_walk.mean():.2f} max {err_walk.max():.2f}; "
        f"standing mean {err_stand.mean():.2f} max {err_stand.max():.2f}; min distance "
        f"{D[:, 1].min():.2f} m; {n_goals} goals ({goals_standing} while the person stood); lost {lost_at and lost_at - visible_until:.2f} s "
        f"after the person was last in sight"
    )
    assert robot.base.collisions == 0
    assert wrong_target == 0
    assert D[:, 1].min() >= 0.5  # never too close
    # keeps up while they walk at 0.5 m/s. Measured 1.82 m before tracks needed evidence of
    # motion to be confirmed, 2.13 m since: the walker is confirmed 0.6 s after setting off
    # (0.2 m walked, docs/people.md) and the base, at 0.6 m/s, gains only 0.1 m/s on them
    assert D[walking, 1].max() <= 2.25
    assert 0.5 <= D[standing, 1].max() <= 1.5  # ends near the standing person
    assert visible_until > t_leave + 1.0  # the person was seen walking away
    assert lost_at is not None and follow.state == "lost"
    assert visible_until < lost_at <= visible_until + 2.0 + 1.0
    assert messages == [(lost_at, LOST_MESSAGE)]
    assert goals_after_lost == 0
    assert goals_standing <= 1  # no re-planning for the tracker's noise on a standing person
