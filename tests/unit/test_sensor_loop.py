"""The one sensor loop (agent/core/sensor_loop.py): association, stamp order, failing steps."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.odom_sync import Matched, SyncParams
from agent.core.sensor_loop import SensorLoop, SensorMessage
from drivers.messages import LaserScan, Pose2D


def _scan(t: float) -> LaserScan:
    return LaserScan(t, int(t * 10), "laser", -1.5, 0.01, 30.0, np.full(301, 2.0, dtype=np.float32))


def test_scans_come_out_in_stamp_order_with_their_interpolated_pose() -> None:
    got: list[Matched] = []
    loop = SensorLoop(SyncParams(reorder=0.3), got.append)
    msgs = [
        SensorMessage("odom", 10.00, Pose2D(0.0, 0.0, 0.0, stamp=10.0)),
        SensorMessage("scan", 10.05, _scan(10.2)),
        SensorMessage("scan", 10.06, _scan(10.1)),  # arrived after a newer one: put in order
        SensorMessage("odom", 10.30, Pose2D(1.0, 0.0, 0.0, stamp=10.3)),
    ]
    for m in msgs:
        loop.feed(m)
    assert got == []  # held for the reorder time
    assert loop.tick(10.5) == 2
    assert [m.scan.stamp for m in got] == [10.1, 10.2]
    assert got[0].pose.x == pytest.approx(1 / 3) and got[1].pose.x == pytest.approx(2 / 3)
    assert (loop.scans, loop.odometry, loop.processed, loop.errors) == (2, 2, 2, 0)


def test_a_failing_step_costs_only_its_scan_and_is_counted() -> None:
    seen: list[float] = []
    failures: list[tuple[float, str]] = []

    def step(m: Matched) -> None:
        if m.scan.stamp == 1.2:
            raise RuntimeError("a strange scan")
        seen.append(m.scan.stamp)

    loop = SensorLoop(None, step, on_error=lambda m, e: failures.append((m.scan.stamp, str(e))))
    loop.odom(Pose2D(0, 0, 0, stamp=1.0), 1.0)
    for t in (1.1, 1.2, 1.3):
        loop.scan(_scan(t), 1.31)
    loop.odom(Pose2D(1, 0, 0, stamp=1.4), 1.41)
    assert seen == [1.1, 1.3] and failures == [(1.2, "a strange scan")]
    assert (loop.processed, loop.errors) == (2, 1)
    with pytest.raises(ValueError, match="scan"):
        loop.feed(SensorMessage("imu", 2.0, Pose2D(0, 0, 0, stamp=2.0)))


def test_close_hands_on_what_odometry_covers_and_drops_the_rest() -> None:
    got: list[Matched] = []
    loop = SensorLoop(SyncParams(max_extrapolation=0.0), got.append)
    loop.odom(Pose2D(0, 0, 0, stamp=1.4), 1.4)
    loop.odom(Pose2D(1, 0, 0, stamp=1.6), 1.6)
    loop.scan(_scan(1.5), 1.6)
    loop.scan(_scan(1.9), 1.7)
    assert loop.pending == 1
    loop.close()
    assert [m.scan.stamp for m in got] == [1.5]
    assert loop.sync.stats.unfinished == 1
