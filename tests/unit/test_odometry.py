"""Odometry: exact arc integration, wheel ticks, and the async pose sources."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.messages import Pose2D, Twist2D
from drivers.odometry import (
    DiffDriveGeometry,
    TickOdometry,
    TwistOdometry,
    arc_step,
    integrate_ticks,
    integrate_twists,
    tick_delta,
    twist_step,
)
from knowledge.errors import DeviceError, DeviceTimeout


def test_straight_line() -> None:
    x, y, th = twist_step((1.0, 2.0, 0.3), 0.5, 0.0, 4.0)
    assert (x, y, th) == pytest.approx((1.0 + 2.0 * math.cos(0.3), 2.0 + 2.0 * math.sin(0.3), 0.3), abs=1e-12)
    # backwards
    x, y, _ = twist_step((0.0, 0.0, math.pi / 2), -1.0, 0.0, 1.5)
    assert (x, y) == pytest.approx((0.0, -1.5), abs=1e-12)


def test_pure_rotation_keeps_position_and_wraps_heading() -> None:
    x, y, th = twist_step((3.0, -1.0, 3.0), 0.0, 1.0, 1.0)
    assert (x, y) == (3.0, -1.0)
    assert th == pytest.approx(4.0 - 2 * math.pi)


def test_arc_matches_closed_form() -> None:
    v, w, t = 0.7, 0.9, 2.3
    x, y, th = twist_step((0.0, 0.0, 0.0), v, w, t)
    r = v / w
    assert (x, y, th) == pytest.approx((r * math.sin(w * t), r * (1 - math.cos(w * t)), w * t), abs=1e-12)


def test_full_circle_returns_to_start_and_euler_does_not() -> None:
    start = (2.0, -1.0, 0.4)
    period, v = 5.0, 0.8
    steps = np.array([0.3, 1.1, 0.05, 2.0, 0.7, 0.85])  # uneven steps summing to the period
    assert steps.sum() == pytest.approx(period)
    traj = integrate_twists(start, np.full(6, v), np.full(6, 2 * math.pi / period), steps)
    assert traj[-1, :2] == pytest.approx(start[:2], abs=1e-12)
    assert traj[-1, 2] == pytest.approx(start[2] + 2 * math.pi)
    # the circle's radius v/ω: every point lies on it
    r = v / (2 * math.pi / period)
    centre = np.array(start[:2]) + r * np.array([-math.sin(start[2]), math.cos(start[2])])
    assert np.hypot(*(traj[:, :2] - centre).T) == pytest.approx(np.full(7, r), abs=1e-12)
    # Euler with the same steps misses by decimetres: the exactness is real
    x, y, th = start
    for dt in steps:
        x, y, th = x + v * dt * math.cos(th), y + v * dt * math.sin(th), th + 2 * math.pi / period * dt
    assert math.hypot(x - start[0], y - start[1]) > 0.1


@settings(max_examples=60, deadline=None)
@given(
    v=st.floats(-2, 2),
    w=st.floats(-3, 3),
    t=st.floats(0.01, 5),
    k=st.integers(1, 20),
)
def test_splitting_a_step_changes_nothing(v: float, w: float, t: float, k: int) -> None:
    one = twist_step((0.5, 0.5, 1.0), v, w, t)
    traj = integrate_twists((0.5, 0.5, 1.0), np.full(k, v), np.full(k, w), t / k)
    assert traj[-1, :2] == pytest.approx(one[:2], abs=1e-9)
    assert math.cos(traj[-1, 2] - one[2]) == pytest.approx(1.0, abs=1e-12)


def test_small_angle_branch_is_continuous() -> None:
    a = arc_step((0.0, 0.0, 0.0), 1.0, 1e-7)
    b = arc_step((0.0, 0.0, 0.0), 1.0, 2e-6)
    assert a[1] == pytest.approx(0.5e-7, rel=1e-6)
    assert b[1] == pytest.approx(1e-6, rel=1e-6)


def test_ticks_and_velocity_integration_agree() -> None:
    geom = DiffDriveGeometry(wheel_radius=0.05, wheel_base=0.32, ticks_per_rev=4096)
    rng = np.random.default_rng(3)
    v = rng.uniform(-0.3, 0.8, 400)
    w = rng.uniform(-1.5, 1.5, 400)
    dt = 0.02
    # encoder counts from the wheel angular speeds, accumulated and truncated to whole ticks
    wl, wr = geom.wheel_speeds(v, w)
    left = np.floor(np.concatenate([[0.0], np.cumsum(wl * dt)]) / (2 * math.pi) * geom.ticks_per_rev)
    right = np.floor(np.concatenate([[0.0], np.cumsum(wr * dt)]) / (2 * math.pi) * geom.ticks_per_rev)
    by_ticks = integrate_ticks((0.0, 0.0, 0.0), left.astype(int), right.astype(int), geom)
    by_twist = integrate_twists((0.0, 0.0, 0.0), v, w, dt)
    assert by_ticks.shape == by_twist.shape
    # one tick is 77 µm of wheel travel: the paths agree to well under a millimetre per metre
    length = float(np.abs(v).sum() * dt)
    err = np.hypot(*(by_ticks[:, :2] - by_twist[:, :2]).T).max()
    assert err < 1e-3 * max(length, 1.0)
    assert np.abs(by_ticks[:, 2] - by_twist[:, 2]).max() < 2e-3


def test_geometry_round_trips() -> None:
    geom = DiffDriveGeometry(0.1, 0.5, 1000)
    dl, dr = geom.arc_to_ticks(0.3, -0.2)
    assert geom.ticks_to_arc(dl, dr) == pytest.approx((0.3, -0.2))
    wl, wr = geom.wheel_speeds(0.4, 1.0)
    assert geom.body_twist(wl, wr) == pytest.approx((0.4, 1.0))
    # a pure turn: wheels opposite; straight: equal
    assert geom.ticks_to_arc(-100, 100)[0] == 0.0
    assert geom.ticks_to_arc(100, 100)[1] == 0.0
    with pytest.raises(ValueError, match="wheel_base"):
        DiffDriveGeometry(0.1, 0.0)


@given(prev=st.integers(0, 65535), d=st.integers(-32767, 32767))
def test_tick_delta_handles_wrap(prev: int, d: int) -> None:
    assert tick_delta(prev, (prev + d) % 65536, bits=16) == d


def test_integrate_ticks_across_a_counter_wrap() -> None:
    geom = DiffDriveGeometry(0.05, 0.3, 1024)
    left = np.arange(65000, 66500, 50)
    right = np.arange(65000, 66800, 60)
    plain = integrate_ticks((0.0, 0.0, 0.0), left, right, geom)
    wrapped = integrate_ticks((0.0, 0.0, 0.0), left % 65536, right % 65536, geom, bits=16)
    assert wrapped == pytest.approx(plain)


def test_twist_odometry_source() -> None:
    async def main() -> None:
        odo = TwistOdometry(Pose2D(0.0, 0.0, 0.0, stamp=100.0), queue_size=2)
        assert odo.latest() is not None and odo.latest().stamp == 100.0  # type: ignore[union-attr]
        odo.command(Twist2D(1.0, 0.0, stamp=100.0))
        odo.command(Twist2D(0.0, math.pi / 2, stamp=102.0))  # 2 m straight, then turn
        odo.advance(103.0)  # 1 s of turning: a quarter turn
        assert odo.drops == 1  # three poses into a queue of two: the oldest went
        first = await odo.recv(timeout=1.0)
        assert (first.x, first.stamp) == pytest.approx((2.0, 102.0))
        last = await odo.recv(timeout=1.0)
        assert (last.x, last.y, last.theta) == pytest.approx((2.0, 0.0, math.pi / 2))
        assert odo.latest() is last
        with pytest.raises(DeviceTimeout):
            await odo.recv(timeout=0.01)
        with pytest.raises(ValueError, match="backwards"):
            odo.advance(50.0)
        await odo.close()
        with pytest.raises(DeviceError, match="closed"):
            await odo.recv(timeout=0.1)
        assert [p async for p in odo] == []

    asyncio.run(main())


def test_tick_odometry_source() -> None:
    async def main() -> None:
        geom = DiffDriveGeometry(0.05, 0.3, 1000)
        odo = TickOdometry(geom, Pose2D(1.0, 1.0, math.pi / 2), bits=16)
        per_metre = 1000 / (2 * math.pi * 0.05)
        odo.feed(65000, 65000, stamp=1.0)
        odo.feed(int(65000 + per_metre) % 65536, int(65000 + per_metre) % 65536, stamp=2.0)
        poses = [await odo.recv(0.5), await odo.recv(0.5)]
        assert (poses[1].x, poses[1].y) == pytest.approx((1.0, 2.0), abs=1e-3)
        assert poses[1].stamp == 2.0

    asyncio.run(main())
