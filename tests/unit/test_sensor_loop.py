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


def _lms_stream(loop: SensorLoop, n: int, *, jitter: float, seed: int, batch: int) -> None:
    """``n`` scans of an LMS at 37.5 Hz with stamp jitter and odometry at 75 Hz, reaching the
    loop in batches of ``batch`` scans (a slow consumer works off a backlog in bigger ones)."""
    rng = np.random.default_rng(seed)
    period = 1 / 37.5
    stamps = 100.0 + np.arange(n) * period + rng.uniform(-jitter, jitter, n)
    odom = 99.9 + np.arange(int((stamps[-1] - 99.9) / (period / 2)) + 3) * (period / 2)
    fed = 0
    for start in range(0, n, batch):
        chunk = stamps[start : start + batch]
        arrival = float(chunk[-1]) + 0.02
        while fed < odom.size and odom[fed] <= chunk[-1] + period:
            t = float(odom[fed])
            loop.odom(Pose2D(0.3 * (t - 99.9), 0.0, 0.0, stamp=t), arrival)
            fed += 1
        for t in chunk:
            loop.scan(_scan(float(t)), arrival)


@pytest.mark.parametrize("batch", [1, 7, 50])
def test_max_rate_steps_the_same_scans_whatever_the_batches(batch: int) -> None:
    got: list[float] = []
    loop = SensorLoop(SyncParams(), lambda m: got.append(m.scan.stamp), max_rate=20.0)
    _lms_stream(loop, 300, jitter=0.004, seed=3, batch=batch)
    loop.close()
    reference: list[float] = []
    ref = SensorLoop(SyncParams(), lambda m: reference.append(m.scan.stamp), max_rate=20.0)
    _lms_stream(ref, 300, jitter=0.004, seed=3, batch=1)
    ref.close()
    assert got == reference
    # every second scan of 37.5 Hz: 150 of 300, the gaps two scan periods
    assert len(got) == 150 and loop.over_rate == 150 and loop.processed == 150
    gaps = np.diff(got)
    assert gaps.min() > 0.045 and gaps.max() < 0.062


def test_max_rate_zero_steps_every_scan_and_a_negative_rate_is_refused() -> None:
    got: list[float] = []
    loop = SensorLoop(SyncParams(), lambda m: got.append(m.scan.stamp))
    _lms_stream(loop, 40, jitter=0.004, seed=1, batch=5)
    loop.close()
    assert len(got) == 40 and loop.over_rate == 0
    with pytest.raises(ValueError, match="max_rate"):
        SensorLoop(None, got.append, max_rate=-1.0)


def test_recordings_carry_max_rate_and_older_ones_step_every_scan() -> None:
    from agent.config import load_config
    from agent.core.pipeline import PipelineParams
    from knowledge.errors import ConfigError

    config = load_config(table={"laser": {"max_rate": 20}}, env={})
    p = PipelineParams.from_config(config)
    assert p.max_rate == 20.0 and p.to_table()["max_rate"] == 20.0
    assert PipelineParams.from_table(p.to_table()) == p
    old = p.to_table()
    del old["max_rate"]
    assert PipelineParams.from_table(old).max_rate == 0.0
    assert "max_rate" not in PipelineParams().to_table()
    with pytest.raises(ConfigError, match="max_rate"):
        load_config(table={"laser": {"max_rate": -5}}, env={})
    with pytest.raises(ConfigError, match="max_rate"):
        PipelineParams.from_table({"max_rate": "fast"})
