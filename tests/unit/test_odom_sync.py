"""Scans get the odometry pose at their stamp, whatever order the messages arrive in."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.odom_sync import OdomSync, interpolate_pose
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
    sync = OdomSync(max_wait=0.2, max_gap=0.5, max_extrapolation=0.0)
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


def test_drops_before_odometry_late_overflow_and_at_close() -> None:
    sync = OdomSync(max_wait=1.0, max_pending=3)
    sync.add_scan(scan(5.0), now=5.0)  # before any odometry
    sync.add_odom(Pose2D(0, 0, 0, stamp=5.5), now=5.5)
    assert sync.stats.before_odometry == 1
    sync.add_odom(Pose2D(0, 0, 0, stamp=5.4), now=5.5)  # odometry going back: ignored
    assert sync.stats.odom_out_of_order == 1
    sync.add_scan(scan(5.6), now=5.6)
    sync.add_scan(scan(5.55), now=5.6)  # older, but 5.6 is still waiting: it goes first
    out = sync.add_odom(Pose2D(1, 0, 0, stamp=5.65), now=5.66)
    assert [m.scan.stamp for m in out] == [5.55, 5.6] and sync.stats.late == 0
    assert sync.add_scan(scan(5.58), now=5.67) == [] and sync.stats.late == 1  # 5.6 was handed on
    assert sync.add_scan(scan(5.6), now=5.67) == [] and sync.stats.duplicate == 1
    for t in (5.7, 5.8, 5.9, 5.95):
        sync.add_scan(scan(t), now=5.96)
    assert sync.stats.overflow == 1 and sync.pending == 3
    # at the end the waiting scans are more than max_extrapolation past the last odometry
    assert sync.close() == [] and sync.stats.unfinished == 3
    s = sync.stats
    assert s.dropped == s.before_odometry + s.late + s.duplicate + s.overflow + s.unfinished == 7
    assert s.scans == s.matched + s.dropped == 9


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


def test_one_future_stamped_odometry_sample_or_scan_stops_nothing() -> None:
    """A single message stamped 10⁶ s ahead (a wrong clock, a forged message) is refused and
    counted; the scans before and after it all get their odometry (issue 18, failure 3)."""
    sync = OdomSync()
    t0, out = 1.75e9, []
    for i in range(200):  # odometry at 50 Hz, scans at 10 Hz, 4 s
        t = t0 + 0.02 * i
        out += sync.add_odom(Pose2D(0.01 * i, 0.0, 0.0, stamp=t), now=t + 0.002)
        if i == 60:
            out += sync.add_odom(Pose2D(5.0, 5.0, 0.0, stamp=t + 1e6), now=t + 0.003)
        if i % 5 == 2:
            out += sync.add_scan(scan(t - 0.01, i), now=t + 0.004)
        if i == 100:
            out += sync.add_scan(scan(t + 1e6, 999), now=t + 0.005)
    out += sync.close()
    assert sync.stats.odom_future == 1 and sync.stats.future_stamp == 1
    assert sync.stats.matched == 40 and sync.stats.dropped == 1
    assert all(abs(m.pose.x - 0.5 * (m.scan.stamp - t0)) < 1e-6 for m in out)


@pytest.mark.parametrize("reorder", [0.0, 1.0])
def test_jittered_scan_stamps_cost_at_most_the_late_scans_themselves(reorder: float) -> None:
    """Scans at 5 Hz arrive in the order they were taken, stamped up to 0.9 s early (a
    jittery clock). Held 1 s, every scan finds its place in stamp order; not held, a scan
    older than one already handed on is dropped as late, and nothing else is lost."""
    rng = np.random.default_rng(7)
    sync = OdomSync(reorder=reorder)
    t0 = 1.75e9
    taken = t0 + 1.0 + 0.2 * np.arange(300)
    stamps = taken - np.where(rng.random(300) < 0.3, rng.uniform(0.0, 0.9, 300), 0.0)
    events = [(t0 + 0.02 * i + 0.002, 0, t0 + 0.02 * i) for i in range(3200)]
    events += [(float(t) + 0.01, 1, float(s)) for t, s in zip(taken, stamps, strict=True)]
    events.sort()
    out = []
    for now, kind, stamp in events:
        if kind == 0:
            out += sync.add_odom(Pose2D(stamp - t0, 0.0, 0.0, stamp=stamp), now)
        else:
            out += sync.add_scan(scan(stamp), now)
    out += sync.close()
    got = [m.scan.stamp for m in out]
    assert got == sorted(got) and len(set(got)) == len(got)
    s = sync.stats
    assert s.scans == 300 == s.matched + s.dropped and s.dropped == s.late
    if reorder:
        assert s.matched == 300
    else:
        running_max = np.maximum.accumulate(stamps)
        older_than_one_before = int((stamps[1:] < running_max[:-1]).sum())
        assert 0 < s.late <= older_than_one_before
    assert all(abs(m.pose.x - (m.scan.stamp - t0)) < 1e-6 for m in out)


def test_a_short_extrapolation_after_max_wait_and_no_more() -> None:
    sync = OdomSync(max_wait=0.2, max_extrapolation=0.1)
    for i in range(6):  # 1 m/s along x, then odometry stops at t = 10.1
        sync.add_odom(Pose2D(0.02 * i, 0.0, 0.0, stamp=10.0 + 0.02 * i), now=10.0 + 0.02 * i)
    assert sync.add_scan(scan(10.15), now=10.16) == []
    assert sync.add_scan(scan(10.3), now=10.31) == []
    out = sync.expire(10.37)  # 10.15 waited 0.21 s: 0.05 s past the last sample, extrapolated
    assert len(out) == 1 and out[0].pose.x == pytest.approx(0.15)
    assert sync.expire(10.52) == [] and sync.stats.no_odometry == 1  # 0.2 s past: too far
    assert sync.stats.extrapolated == 1 and sync.stats.matched == 1


def test_a_robot_that_stood_still_across_a_long_odometry_gap_keeps_its_scans() -> None:
    """A base that only reports motion leaves long gaps while the robot stands: the pose
    there is known, so the scans are matched; across a gap with motion they are dropped."""
    sync = OdomSync(max_gap=0.5)
    sync.add_odom(Pose2D(1.0, 2.0, 0.5, stamp=100.0), now=100.0)
    sync.add_scan(scan(101.0), now=101.0)
    out = sync.add_odom(Pose2D(1.0, 2.0, 0.5, stamp=101.1), now=101.1)
    assert len(out) == 1 and (out[0].pose.x, out[0].pose.y, out[0].pose.theta) == pytest.approx((1, 2, 0.5))
    sync.add_scan(scan(102.0), now=102.0)
    assert sync.add_odom(Pose2D(2.0, 2.0, 0.5, stamp=102.1), now=102.1) == []
    assert sync.stats.odom_gap == 1


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["odom", "scan", "tick"]),
            st.floats(-2.0, 2.0),  # stamp offset from the arrival time
            st.floats(0.0, 0.3),  # time since the previous message
        ),
        max_size=120,
    ),
    st.sampled_from([0.0, 0.5]),
)
def test_every_scan_is_accounted_for_and_handed_on_in_stamp_order(
    messages: list[tuple[str, float, float]], reorder: float
) -> None:
    """Whatever the stamps (late, repeated, ahead, behind): the counters add up after every
    message, and the scans handed on have strictly increasing stamps, each with a pose no
    farther from the odometry it came from than the extrapolation allows."""
    sync = OdomSync(reorder=reorder)
    now, out = 1000.0, []
    for kind, offset, dt in messages:
        now += dt
        stamp = round(now + offset, 2)
        if kind == "odom":
            out += sync.add_odom(Pose2D(stamp - 1000.0, 0.0, 0.0, stamp=stamp), now)
        elif kind == "scan":
            out += sync.add_scan(scan(stamp), now)
        else:
            out += sync.expire(now)
        s = sync.stats
        assert s.scans == s.matched + s.dropped + sync.pending
    out += sync.close()
    s = sync.stats
    assert s.scans == s.matched + s.dropped and sync.pending == 0
    got = [m.scan.stamp for m in out]
    assert all(a < b for a, b in itertools.pairwise(got)) and len(out) == s.matched
    # odometry moves at 1 m/s: interpolation is exact, a held or extrapolated pose is off by
    # at most the extrapolation time
    assert all(abs(m.pose.x - (m.scan.stamp - 1000.0)) <= sync.params.max_extrapolation + 1e-6 for m in out)
