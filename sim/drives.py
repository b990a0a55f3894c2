"""Scans of a simulated robot touring a generated office, as the LMS driver gives them.

:class:`DriveScans` drives :class:`sim.robot.SimRobot` round a generated office in a loop
(exact odometry) and casts a 180°/0.5° SICK LMS scan (361 beams) at each pose, ranges in
whole centimetres as the driver decodes them from telegrams: the input of the agent's
benchmarks (``tools/bench_agent.py``) and of the tests that run the agent's per-scan path on
realistic scans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.messages import LaserScan, Pose2D
from drivers.sick import telegrams as tg
from drivers.sick.constants import MIRROR_HZ, UNIT_METRES, Units
from drivers.sim.base import OdometryNoise
from knowledge.metric.raycast import cast
from sim.robot import SimRobot, SimRobotConfig

#: The LMS 2xx at 180°/0.5°: beams, scans per second, range maximum in centimetre units.
N_BEAMS = 361
LMS_HZ = 37.5
RANGE_MAX = tg.range_max_m(Units.CM)


@dataclass(frozen=True, eq=False)
class Chunk:
    """Scans of a stretch of driving: ``(n,)`` stamps, ``n`` odometry poses, ``(n, 361)`` ranges."""

    stamps: np.ndarray
    odom: list[Pose2D]
    ranges: np.ndarray

    def __len__(self) -> int:
        return len(self.odom)


class DriveScans:
    """Front-laser scans of a simulated robot touring a generated office in a loop.

    Args:
        building: seed of the generated office.
        scan_hz: scans per simulated second.
        noise: range noise, metres.
        seed: seeds the noise.
    """

    def __init__(
        self, building: int = 3, scan_hz: float = LMS_HZ, *, noise: float = 0.01, seed: int = 0
    ) -> None:
        k = max(1, math.ceil(20.0 / scan_hz))
        self.every = k
        self.robot = SimRobot(
            SimRobotConfig(
                world=f"gen:{building}",
                tour=True,
                loop=True,
                odom_rate=scan_hz * k,
                odom_noise=OdometryNoise(0.0, 0.0, 0.0),
                seed=seed,
            )
        )
        self.noise = noise
        self.rng = np.random.default_rng(seed)
        self.seq = 0

    @property
    def lap_seconds(self) -> float:
        """Simulated seconds of one lap, estimated from the route's length at full speed."""
        route = self.robot.route
        assert route is not None
        return route.length / self.robot.base.limits.v_max

    def take(self, n: int) -> Chunk:
        """The next ``n`` scans of the drive."""
        stamps = np.empty(n)
        poses = np.empty((n, 3))
        odom: list[Pose2D] = []
        for i in range(n):
            for _ in range(self.every):
                sample = self.robot.step()
            stamps[i] = sample.stamp
            poses[i] = self.robot.sensor_pose
            odom.append(sample.odom)
        ranges = cast(
            self.robot.grid,
            poses,
            n_beams=N_BEAMS,
            fov=math.pi,
            max_range=RANGE_MAX,
            noise_std=self.noise,
            rng=self.rng,
        )
        return Chunk(stamps, odom, ranges)

    def scan(self, chunk: Chunk, i: int) -> LaserScan:
        """Scan ``i`` of a chunk as the LMS driver would give it (ranges in whole centimetres)."""
        self.seq += 1
        values = telegram_values(chunk.ranges[i])
        ranges, _ = tg.values_to_ranges(values, Units.CM)
        return make_scan(ranges, float(chunk.stamps[i]), self.seq)


def telegram_values(ranges: np.ndarray) -> np.ndarray:
    """Metres → the 0xB0 words a scanner sends (nothing within range: "value > maximum")."""
    return tg.ranges_to_values(np.where(ranges >= RANGE_MAX, np.inf, ranges), Units.CM)


def make_scan(ranges: np.ndarray, stamp: float, seq: int) -> LaserScan:
    """A 180°/0.5° scan with the geometry :class:`~drivers.sick.driver.LMS2xx` gives it."""
    turns = tg.scan_revolutions(180, 50)
    return LaserScan(
        stamp=stamp,
        seq=seq,
        frame_id="laser",
        angle_min=tg.angle_min_rad(180),
        angle_increment=math.radians(0.5),
        range_max=RANGE_MAX,
        ranges=ranges,
        range_min=UNIT_METRES[Units.CM],
        scan_time=turns / MIRROR_HZ,
    )
