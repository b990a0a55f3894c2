"""The simulated robot's clock: a step is stamped with the time it simulates, whoever computes
it when, and the lasers see the world at the time they measure (issue 24: a simulator thread
that stalled 0.32 s published 25 catch-up steps stamped 1 ms apart)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.robot import MAX_CATCH_UP, RobotSample, SimRobot, SimRobotConfig


def _robot(speed: float = 1.5) -> tuple[SimRobot, list[RobotSample]]:
    robot = SimRobot(SimRobotConfig(world="demo:0", laser="360", scan_rate=1.0, speed=speed))
    samples: list[RobotSample] = []
    robot.sample_listeners.append(samples.append)
    robot.command_velocity(0.4, 0.3)
    return robot, samples


def test_catching_up_stamps_each_step_with_the_time_it_simulates() -> None:
    robot, samples = _robot()
    dt = robot.dt / robot.config.speed  # wall seconds per step
    t0 = robot.origin
    robot.advance_to(t0 + 0.1)
    n = len(samples)
    robot.advance_to(t0 + 0.1 + 0.32)  # a thread that stalled 0.32 s catches up at once
    caught = samples[n:]
    stamps = np.array([s.stamp for s in caught])
    assert len(caught) == pytest.approx(0.32 / dt, abs=1)
    assert np.allclose(np.diff(stamps), dt, atol=1e-6)  # spaced as simulated, not as computed
    assert stamps[-1] <= t0 + 0.42 + 1e-9
    for s in samples:
        assert s.stamp == pytest.approx(t0 + s.time / robot.config.speed)


def test_more_than_max_catch_up_behind_the_world_stands_still_over_the_gap() -> None:
    robot, samples = _robot()
    t0 = robot.origin
    robot.advance_to(t0 + 0.5)
    before = samples[-1]
    robot.advance_to(t0 + 0.5 + MAX_CATCH_UP + 3.0)
    after = samples[-1]
    # the robot drove only what the catch-up allows, the stamps reach the requested time
    assert after.time - before.time < (MAX_CATCH_UP + 0.1) * robot.config.speed
    assert after.stamp == pytest.approx(t0 + 3.5 + MAX_CATCH_UP, abs=robot.dt)


def test_the_laser_sees_the_pose_at_the_time_it_measures() -> None:
    robot, samples = _robot()
    t0 = robot.origin
    robot.advance_to(t0 + 1.0)
    a, b = samples[-20], samples[-19]
    mid = 0.5 * (a.stamp + b.stamp)
    x, y, th = robot.sensor_pose_at(mid)
    mount = robot.config.mount
    pa, pb = (
        mount.apply((a.truth.x, a.truth.y, a.truth.theta)),
        mount.apply((b.truth.x, b.truth.y, b.truth.theta)),
    )
    assert (x, y) == pytest.approx(((pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2), abs=1e-9)
    assert th == pytest.approx((pa[2] + pb[2]) / 2, abs=1e-9)
    # beyond the newest step: the newest pose (a laser never sees the future)
    newest = samples[-1].truth
    assert robot.sensor_pose_at(t0 + 5.0)[:2] == pytest.approx(
        mount.apply((newest.x, newest.y, newest.theta))[:2]
    )
    assert math.isfinite(robot.legs_at(mid).sum())
