"""Scans get the odometry pose at their stamp, whatever order the messages arrive in."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.odom_sync import OdomSync, interpolate_pose
from drivers.messages import LaserScan, Pose2D


def scan(stamp: float, seq: int = 0) -> LaserScan:
    return LaserScan(stamp, seq, "laser", -math.pi / 2, math.pi / 360, 30.0, np.ones(361, dtype=np.float32))


def test_interpolation_is_linear_in_position_and_takes_the_short_arc() -> None:
    a = Pose2D(0.0, 0.0, 0.0, stamp=10.0)
    b = Pose2D(1.0, 2.0, math.pi / 2, stamp=11.0)
    p = interpolate_pose(a, b, 10.25)
    assert (p.x, p.y, p.theta, p.stamp) == pytest.approx((0.25, 0.5, math.pi / 8, 10.25))
    # across ±π: 3.0 → -3.0 turns by 0.28 rad through π, not by 6 rad through 0
    mid = interpolate_pose(Pose2D(0, 0, 3.0, stamp=0.0), Pose2D(0, 0, -3.0, stamp=1.0), 0.5)
    assert abs(abs(mid.theta) - math.pi) < 1e-9


def test_a_scan_waits_for_newer_odometry_then_gets_the_pose_at_its_stamp() -> None:
    sync = OdomSync(max_wait=0.2)
    assert sync.add_odom(Pose2D(0.0, 0.0, 0.0, stamp=100.0), now=100.01) == []
    assert sync.add_scan(scan(100.05), now=100.06) == []  # odometry is not past the scan yet
    assert sync.pending == 1
    out = sync.add_odom(Pose2D(1.0, 0.0, 0.0, stamp=100.1), now=100.11)
    assert len(out) == 1 and sync.pending == 0
    assert (out[0].pose.x, out[0].pose.stamp) == pytest.approx((0.5, 100.05))
    # odometry already ahead: matched at once; an exact stamp takes the sample itself
    out = sync.add_scan(scan(100.1), now=100.12)
    assert out[0].pose.x == 1.0 and out[0].scan.stamp == 100.1
    assert sync.stats.matched == 2 and sync.stats.dropped == 0


def test_when_odometry_stops_scans_are_dropped_after_max_wait_and_processing_resumes() -> None:
    sync = OdomSync(max_wait=0.2, max_gap=0.5)
    for i in range(5):
        sync.add_odom(Pose2D(0.1 * i, 0.0, 0.0, stamp=10.0 + 0.1 * i), now=10.0 + 0.1 * i)
    # odometry stops at 10.4; scans keep coming every 0.1 s
    for i in range(5, 15):
        assert sync.add_scan(scan(10.0 + 0.1 * i), now=10.01 + 0.1 * i) == []
    sync.expire(11.6)
    assert sync.pending == 1 and sync.stats.no_odometry == 9  # the last one has waited 0.19 s
    sync.expire(11.65)
    assert sync.pending == 0 and sync.stats.no_odometry == 10
    # odometry comes back after a 1.1 s break: a scan inside the break is not interpolated across it
    sync.add_scan(scan(11.45), now=11.66)
    out = sync.add_odom(Pose2D(1.5, 0.0, 0.0, stamp=11.5), now=11.67)
    assert out == [] and sync.stats.odom_gap == 1
    out = sync.add_scan(scan(11.55), now=11.68)
    assert out == []
    out = sync.add_odom(Pose2D(1.6, 0.0, 0.0, stamp=11.6), now=11.69)
    assert len(out) == 1 and out[0].pose.x == pytest.approx(1.55)
    assert sync.stats.matched == 1


def test_drops_before_odometry_out_of_order_overflow_and_at_close() -> None:
    sync = OdomSync(max_wait=1.0, max_pending=3)
    sync.add_scan(scan(5.0), now=5.0)  # before any odometry
    sync.add_odom(Pose2D(0, 0, 0, stamp=5.5), now=5.5)
    assert sync.stats.before_odometry == 1
    sync.add_odom(Pose2D(0, 0, 0, stamp=5.4), now=5.5)  # odometry going back: ignored
    assert sync.stats.odom_out_of_order == 1
    sync.add_scan(scan(5.6), now=5.6)
    sync.add_scan(scan(5.55), now=5.6)  # a scan going back
    assert sync.stats.out_of_order == 1
    for t in (5.7, 5.8, 5.9):
        sync.add_scan(scan(t), now=5.9)
    assert sync.stats.overflow == 1 and sync.pending == 3
    assert sync.close() == 3 and sync.stats.unfinished == 3
    s = sync.stats
    assert s.dropped == s.before_odometry + s.out_of_order + s.overflow + s.unfinished == 6


def test_old_odometry_is_forgotten() -> None:
    sync = OdomSync(horizon=2.0)
    for i in range(1000):
        t = 0.02 * i
        sync.add_odom(Pose2D(t, 0.0, 0.0, stamp=t), now=t)
        if i % 5 == 0:
            sync.add_scan(scan(t - 0.01), now=t)
    assert sync.stats.matched == 199 and sync.buffered <= 6
    # without scans, the horizon bounds what is kept
    quiet = OdomSync(horizon=2.0)
    for i in range(1000):
        quiet.add_odom(Pose2D(0, 0, 0, stamp=0.02 * i), now=0.02 * i)
    assert quiet.buffered <= 101


@settings(max_examples=40, deadline=None)
@given(
    odom_dt=st.lists(st.floats(0.005, 0.05), min_size=5, max_size=40),
    scan_at=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
    latency=st.lists(st.floats(0.0, 0.08), min_size=60, max_size=60),
)
def test_poses_depend_on_stamps_not_on_arrival_order(
    odom_dt: list[float], scan_at: list[float], latency: list[float]
) -> None:
    """Each stream arrives in order with random delays below max_wait, the two streams
    interleaved in any way; every scan gets the pose interpolated at its stamp (computed
    here with np.interp)."""
    t = 50.0 + np.cumsum([0.0, *odom_dt])
    x, y, th = np.cos(t), 2.0 * t, np.unwrap(3.0 * t)
    stamps = sorted({float(t[0] + f * (t[-1] - t[0])) for f in scan_at})
    events: list[tuple[float, int, object]] = []
    arrive = 0.0
    for i, ti in enumerate(t):
        arrive = max(arrive, ti + latency[i % 60])
        events.append((arrive, 0, Pose2D(x[i], y[i], th[i], stamp=float(ti))))
    arrive = 0.0
    for j, s in enumerate(stamps):
        arrive = max(arrive, s + latency[(j * 7 + 3) % 60])
        events.append((arrive, 1, scan(s, j)))
    events.sort(key=lambda e: (e[0], e[1]))
    sync = OdomSync(max_wait=0.2, max_gap=1.0)
    out = []
    for now, kind, msg in events:
        out.extend(sync.add_odom(msg, now) if kind == 0 else sync.add_scan(msg, now))  # type: ignore[arg-type]
    assert sync.stats.dropped == 0
    assert [m.scan.stamp for m in out] == stamps
    got = np.array([[m.pose.x, m.pose.y, m.pose.theta] for m in out])
    want_x = np.interp(stamps, t, x)
    want_y = np.interp(stamps, t, y)
    want_th = np.interp(stamps, t, th)
    assert np.allclose(got[:, 0], want_x, atol=1e-9) and np.allclose(got[:, 1], want_y, atol=1e-9)
    dth = np.angle(np.exp(1j * (got[:, 2] - want_th)))
    assert np.allclose(dth, 0.0, atol=1e-9)
