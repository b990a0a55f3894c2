"""The simulated base: goals, paths, walls, limits, odometry noise and determinism."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np
import pytest

from drivers.messages import Pose2D, Twist2D
from drivers.sim.base import (
    BaseLimits,
    BaseStatus,
    ControllerParams,
    OdometryNoise,
    SimBase,
    SimBaseRunner,
)
from knowledge.errors import DeviceTimeout
from knowledge.metric.grid import OccupancyGrid
from sim.world import SimWorld, demo_world

QUIET = OdometryNoise(0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def flat() -> SimWorld:
    return demo_world()


@pytest.mark.parametrize(
    ("start", "goal"),
    [
        (Pose2D(1.0, 1.0, 0.0), Pose2D(4.5, 1.2, math.pi / 2)),
        (Pose2D(4.0, 1.0, math.pi), Pose2D(1.0, 1.5, -math.pi / 2)),  # goal behind: turn first
        (Pose2D(2.0, 4.0, 1.0), Pose2D(2.3, 4.1, -2.5)),  # short hop, big final turn
    ],
)
def test_reaches_a_goal_within_tolerance(flat: SimWorld, start: Pose2D, goal: Pose2D) -> None:
    base = SimBase(flat, start, seed=4)
    base.go_to(goal)
    state = base.run_until_done(timeout=60.0)
    c = base.control
    assert state.status is BaseStatus.REACHED and state.event is not None and "reached" in state.event
    assert math.hypot(state.true_pose.x - goal.x, state.true_pose.y - goal.y) <= c.goal_tolerance + 1e-9
    assert abs(math.remainder(state.true_pose.theta - goal.theta, 2 * math.pi)) <= c.yaw_tolerance
    assert state.twist.v == pytest.approx(0.0, abs=0.02)
    # the base stays put once it is there
    assert base.step(0.1).true_pose.x == pytest.approx(state.true_pose.x, abs=1e-3)


def test_follows_a_waypoint_path_through_a_doorway(flat: SimWorld) -> None:
    # corridor → living-room doorway (x 2.5–3.4 at y = 2) → up to the couch
    path = [(1.5, 1.0), (2.95, 1.2), (2.95, 2.8), (2.0, 5.5)]
    base = SimBase(flat, Pose2D(0.6, 1.0, 0.0), seed=1)
    base.follow_path(path)
    traj = []
    events = []
    for _ in range(5000):
        s = base.step(0.02)
        traj.append((s.true_pose.x, s.true_pose.y))
        if s.event:
            events.append(s.event)
        if s.status is not BaseStatus.GOAL:
            break
    assert s.status is BaseStatus.REACHED, events
    pts = np.array(traj)
    for k, wp in enumerate(path[:-1]):
        closest = np.hypot(*(pts - wp).T).min()
        assert closest <= base.control.waypoint_tolerance + 0.02, f"waypoint {k} missed by {closest:.2f} m"
    assert sum("waypoint" in e for e in events) == len(path) - 1
    assert math.hypot(s.true_pose.x - 2.0, s.true_pose.y - 5.5) <= base.control.goal_tolerance
    assert base.collisions == 0
    # it never came closer to a wall than its radius
    assert flat.clearance(pts).min() >= base.radius - 1e-9


def test_stops_at_a_wall_and_says_so(flat: SimWorld) -> None:
    base = SimBase(flat, Pose2D(4.0, 5.0, 0.0), radius=0.25, noise=QUIET)
    base.command_velocity(Twist2D(0.5, 0.0))
    states = [base.step(0.05) for _ in range(200)]
    hits = [s for s in states if s.status is BaseStatus.COLLIDED]
    assert hits and hits[0].event is not None and "collision" in hits[0].event
    assert base.collisions == 1
    # stopped in front of the wall at x = 6 m: not in it, and not far from it
    x = states[-1].true_pose.x
    assert 6.0 - 0.25 - 0.1 <= x < 6.0 - 0.25 + 1e-9
    assert states[-1].twist.v == 0.0 and states[-1].true_pose.x == hits[0].true_pose.x
    # backing off is allowed
    base.command_velocity(Twist2D(-0.3, 0.0))
    for _ in range(20):
        s = base.step(0.05)
    assert s.status is BaseStatus.VELOCITY and s.true_pose.x < x - 0.1


def test_a_goal_through_a_wall_ends_in_a_collision(flat: SimWorld) -> None:
    base = SimBase(flat, Pose2D(4.5, 1.0, math.pi / 2), control=ControllerParams(turn_threshold=0.3))
    base.go_to((4.5, 4.0))  # straight up through the corridor wall at y = 2
    state = base.run_until_done(timeout=30.0)
    assert state.status is BaseStatus.COLLIDED
    assert state.true_pose.y < 2.0 - base.radius + 1e-9


def test_velocity_and_acceleration_limits() -> None:
    lim = BaseLimits(v_max=0.5, omega_max=1.0, accel=0.5, alpha=2.0)
    base = SimBase(None, Pose2D(0.0, 0.0, 0.0), limits=lim, noise=QUIET)
    base.command_velocity(Twist2D(5.0, -9.0))
    vs, ws = [0.0], [0.0]
    for _ in range(100):
        s = base.step(0.05)
        vs.append(s.twist.v)
        ws.append(s.twist.omega)
    assert max(vs) == pytest.approx(0.5) and min(ws) == pytest.approx(-1.0)
    assert np.abs(np.diff(vs)).max() <= 0.5 * 0.05 + 1e-12
    assert np.abs(np.diff(ws)).max() <= 2.0 * 0.05 + 1e-12


def test_stale_velocity_commands_time_out() -> None:
    base = SimBase(None, Pose2D(0.0, 0.0, 0.0), cmd_timeout=0.5)
    base.command_velocity(Twist2D(0.4, 0.0))
    events = [base.step(0.1).event for _ in range(30)]
    assert any(e and "older than 0.5 s" in e for e in events)
    assert base.status is BaseStatus.IDLE and base.twist.v == 0.0


def _drive(noise: OdometryNoise, seed: int, v: float, omega: float, seconds: float) -> tuple[Pose2D, Pose2D]:
    base = SimBase(
        None, Pose2D(0.0, 0.0, 0.0), noise=noise, seed=seed, limits=BaseLimits(accel=100.0, alpha=100.0)
    )
    base.command_velocity(Twist2D(v, omega))
    for _ in range(round(seconds / 0.05)):
        s = base.step(0.05)
    return s.true_pose, s.odom


def test_odometry_drift_statistics_match_the_configured_noise() -> None:
    n = 150
    # distance noise only: 2 m straight
    err = []
    for seed in range(n):
        true, odom = _drive(OdometryNoise(dist_std=0.03, turn_std=0.0, drift_std=0.0), seed, 0.5, 0.0, 4.0)
        assert odom.theta == pytest.approx(true.theta, abs=1e-12)
        err.append(odom.x - true.x)
    assert np.std(err) == pytest.approx(0.03 * math.sqrt(2.0), rel=0.2)
    assert abs(np.mean(err)) < 3 * 0.03 * math.sqrt(2.0) / math.sqrt(n)
    # heading drift while driving: 2 m straight
    dth = [
        _drive(OdometryNoise(dist_std=0.0, turn_std=0.0, drift_std=0.02), seed, 0.5, 0.0, 4.0)[1].theta
        for seed in range(n)
    ]
    assert np.std(dth) == pytest.approx(0.02 * math.sqrt(2.0), rel=0.2)
    # turning in place: 2π rad
    turn = []
    for seed in range(n):
        true, odom = _drive(
            OdometryNoise(dist_std=0.0, turn_std=0.03, drift_std=0.0), seed, 0.0, math.pi / 2, 4.0
        )
        turn.append(math.remainder(odom.theta - true.theta, 2 * math.pi))
        assert (odom.x, odom.y) == (true.x, true.y)
    assert np.std(turn) == pytest.approx(0.03 * math.sqrt(2 * math.pi), rel=0.2)


def test_odometry_differs_from_the_truth_and_is_deterministic(flat: SimWorld) -> None:
    def run(seed: int) -> list[tuple[float, ...]]:
        base = SimBase(flat, Pose2D(1.0, 1.0, 0.0), seed=seed)
        base.follow_path([(4.0, 1.0), (4.0, 1.5)])
        out = []
        for _ in range(400):
            s = base.step(0.05)
            out.append((*s.true_pose.as_array(), *s.odom.as_array()))
        return out

    a, b, c = np.array(run(7)), np.array(run(7)), np.array(run(8))
    assert np.array_equal(a, b)
    assert np.array_equal(a[:, :3], c[:, :3])  # the noise touches the odometry, never the truth
    assert not np.array_equal(a[:, 3:], c[:, 3:])
    drift = np.hypot(a[-1, 3] - a[-1, 0], a[-1, 4] - a[-1, 1])
    assert 1e-4 < drift < 0.5


def test_bad_arguments() -> None:
    base = SimBase(None, Pose2D(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="dt"):
        base.step(0.0)
    with pytest.raises(ValueError, match="at least one waypoint"):
        base.follow_path([])
    with pytest.raises(ValueError, match="finite"):
        base.command_velocity(Twist2D(math.nan, 0.0))
    with pytest.raises(ValueError, match="v_max"):
        BaseLimits(v_max=0.0)


def test_runner_as_fast_as_possible_publishes_odometry(flat: SimWorld) -> None:
    async def main() -> None:
        base = SimBase(flat, Pose2D(1.0, 1.0, 0.0), seed=2)
        runner = SimBaseRunner(base, rate_hz=50.0, realtime=False, queue_size=10_000)
        task = asyncio.create_task(runner.run())
        base.go_to(Pose2D(3.0, 1.2, 0.0))
        state = await runner.wait_done(timeout=10.0)
        assert state.status is BaseStatus.REACHED
        await runner.close()
        await task
        poses = [p async for p in runner]
        assert len(poses) == runner.published and poses[-1] is runner.latest()
        assert [p.stamp for p in poses] == pytest.approx(np.arange(1, len(poses) + 1) * 0.02)
        assert all(p.frame_id == "odom" for p in poses)
        assert math.hypot(poses[-1].x - 3.0, poses[-1].y - 1.2) < 0.2  # odometry: near, not exact

    asyncio.run(main())


def test_runner_in_real_time(flat: SimWorld) -> None:
    async def main() -> None:
        base = SimBase(flat, Pose2D(1.0, 1.0, 0.0))
        runner = SimBaseRunner(base, rate_hz=50.0, realtime=True)
        base.command_velocity(Twist2D(0.2, 0.0))
        t0 = time.time()
        await runner.run(duration=0.3)
        elapsed = time.time() - t0
        assert elapsed >= 0.27
        pose = await runner.recv(timeout=0.1)
        assert abs(pose.stamp - t0) < 1.0  # stamps are wall-clock seconds
        assert base.time == pytest.approx(0.3)
        with pytest.raises(DeviceTimeout):
            base.go_to((2.0, 1.0))
            await runner.wait_done(timeout=0.05)  # nobody is stepping the base

    asyncio.run(main())


def test_unknown_world_edges_block() -> None:
    grid = OccupancyGrid.from_masks(np.zeros((40, 40), bool), 0.05)  # 2 m × 2 m, no walls at all
    base = SimBase(SimWorld(grid), Pose2D(1.0, 1.0, 0.0), radius=0.1, noise=QUIET)
    base.command_velocity(Twist2D(0.5, 0.0))
    for _ in range(100):
        s = base.step(0.05)
    assert s.status is BaseStatus.COLLIDED and s.true_pose.x < 2.0
