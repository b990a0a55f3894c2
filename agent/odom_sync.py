"""Each scan with the odometry pose at the scan's stamp.

Scans and odometry come from different devices at different rates. :class:`OdomSync`
gives every scan the robot's odometry pose **at the scan's stamp**, interpolated between
the two odometry samples around it (position linearly, heading along the shorter arc). A
scan therefore waits until odometry newer than its stamp has arrived, for at most
``max_wait`` seconds of arrival time, and scans leave in the order they came.

Why stamps and not arrival times: the pose then depends only on the scan and odometry
messages, never on when they happened to be delivered, so a live run and a replay of its
recording (:mod:`agent.commands.replay`) give every scan the same pose. The only decision
that depends on arrival times is the timeout, and the replay takes it with the recorded
arrival times (MCAP log times).

What happens to a scan:

* **matched**: odometry newer than its stamp arrived in time; it is interpolated.
* **no_odometry**: none arrived within ``max_wait`` (odometry stopped or lags): the scan is
  dropped. While odometry is stopped every scan is dropped this way, and counted; the
  agent's state does not change and nothing is published for these scans. Processing
  resumes by itself with the first scan that odometry catches up with.
* **odom_gap**: the two samples around it are more than ``max_gap`` apart (odometry
  resumed after a break): dropped rather than interpolated across the break.
* **before_odometry**: its stamp is older than every odometry sample kept (the laser
  started before the base, or the scan is older than ``horizon``): dropped.
* **out_of_order**: its stamp is not after the previous scan's: dropped (the local map
  needs time to run forwards).
* **overflow**: more than ``max_pending`` scans waiting: the oldest is dropped.
* **unfinished**: still waiting when :meth:`OdomSync.close` is called (shutdown, end of a
  recording): dropped.

Odometry samples whose stamp is not after the newest one are ignored (``odom_out_of_order``).
Odometry older than the sample before the last matched scan, or older than ``horizon``
seconds before the newest sample, is forgotten (decided by stamps, so replay forgets the
same samples).

Times: stamps and ``now`` are seconds since the Unix epoch (the same clock for odometry,
scans and arrival times, as on one host).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import asdict, dataclass

from drivers.messages import LaserScan, Pose2D

__all__ = ["Matched", "OdomSync", "SyncStats", "interpolate_pose"]


@dataclass(frozen=True)
class Matched:
    """A scan and the odometry pose at its stamp (``pose.stamp == scan.stamp``)."""

    scan: LaserScan
    pose: Pose2D


@dataclass
class SyncStats:
    """Counters of :class:`OdomSync` (see the module docstring for each outcome)."""

    scans: int = 0
    matched: int = 0
    no_odometry: int = 0
    odom_gap: int = 0
    before_odometry: int = 0
    out_of_order: int = 0
    overflow: int = 0
    unfinished: int = 0
    odom: int = 0
    odom_out_of_order: int = 0

    @property
    def dropped(self) -> int:
        """Scans that were not matched, for whatever reason."""
        return (
            self.no_odometry
            + self.odom_gap
            + self.before_odometry
            + self.out_of_order
            + self.overflow
            + self.unfinished
        )

    def as_dict(self) -> dict[str, int]:
        return {**asdict(self), "dropped": self.dropped}


def interpolate_pose(a: Pose2D, b: Pose2D, stamp: float) -> Pose2D:
    """The pose at ``stamp`` between ``a`` and ``b`` (``a.stamp <= stamp <= b.stamp``):
    position linear in time, heading along the shorter arc."""
    span = b.stamp - a.stamp
    f = 0.0 if span <= 0 else (stamp - a.stamp) / span
    dth = math.atan2(math.sin(b.theta - a.theta), math.cos(b.theta - a.theta))
    return Pose2D(
        a.x + f * (b.x - a.x),
        a.y + f * (b.y - a.y),
        a.theta + f * dth,
        stamp=stamp,
        frame_id=a.frame_id,
    )


class OdomSync:
    """Associates scans with odometry by stamp (see the module docstring).

    Feed it in arrival order: :meth:`add_odom`, :meth:`add_scan` (each returns the scans
    now matched, oldest first) and :meth:`expire` when time passes without messages.

    Args:
        max_wait: seconds (arrival time) a scan waits for newer odometry.
        max_gap: seconds; the longest odometry interval a scan is interpolated across.
        horizon: seconds of odometry kept before the newest sample.
        max_pending: the most scans waiting at once.
    """

    def __init__(
        self, *, max_wait: float = 0.2, max_gap: float = 0.5, horizon: float = 10.0, max_pending: int = 256
    ) -> None:
        for name, v in (("max_wait", max_wait), ("max_gap", max_gap), ("horizon", horizon)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1 scan, got {max_pending}")
        self.max_wait = float(max_wait)
        self.max_gap = float(max_gap)
        self.horizon = float(horizon)
        self.max_pending = int(max_pending)
        self.stats = SyncStats()
        self._stamps: list[float] = []
        self._poses: list[Pose2D] = []
        self._pending: deque[tuple[LaserScan, float]] = deque()
        self._last_scan: float | None = None
        self._now = -math.inf

    @property
    def pending(self) -> int:
        """Scans waiting for odometry."""
        return len(self._pending)

    @property
    def buffered(self) -> int:
        """Odometry samples kept."""
        return len(self._stamps)

    @property
    def latest_odom(self) -> Pose2D | None:
        """The newest odometry sample."""
        return self._poses[-1] if self._poses else None

    def _tick(self, now: float) -> None:
        self._now = max(self._now, float(now))
        while self._pending and self._now - self._pending[0][1] > self.max_wait:
            self._pending.popleft()
            self.stats.no_odometry += 1

    def expire(self, now: float) -> None:
        """Drop the scans that have waited more than ``max_wait`` by ``now``."""
        self._tick(now)

    def add_odom(self, pose: Pose2D, now: float) -> list[Matched]:
        """An odometry sample arrived at ``now``; returns the scans it completes."""
        self._tick(now)
        if self._stamps and pose.stamp <= self._stamps[-1]:
            self.stats.odom_out_of_order += 1
            return []
        self.stats.odom += 1
        self._stamps.append(pose.stamp)
        self._poses.append(pose)
        return self._release()

    def add_scan(self, scan: LaserScan, now: float) -> list[Matched]:
        """A scan arrived at ``now``; returns the scans matched now (this one, if odometry is ahead)."""
        self._tick(now)
        self.stats.scans += 1
        if self._last_scan is not None and scan.stamp <= self._last_scan:
            self.stats.out_of_order += 1
            return []
        self._last_scan = scan.stamp
        self._pending.append((scan, self._now))
        if len(self._pending) > self.max_pending:
            self._pending.popleft()
            self.stats.overflow += 1
        return self._release()

    def close(self) -> int:
        """Drop the scans still waiting (shutdown, end of a recording); returns how many."""
        n = len(self._pending)
        self._pending.clear()
        self.stats.unfinished += n
        return n

    def _release(self) -> list[Matched]:
        out: list[Matched] = []
        stamps = self._stamps
        while self._pending and stamps and stamps[-1] >= self._pending[0][0].stamp:
            scan, _ = self._pending.popleft()
            i = bisect.bisect_right(stamps, scan.stamp)
            if i == 0:
                self.stats.before_odometry += 1
                continue
            a = self._poses[i - 1]
            if a.stamp == scan.stamp:
                pose = Pose2D(a.x, a.y, a.theta, stamp=scan.stamp, frame_id=a.frame_id)
            else:
                b = self._poses[i]
                if b.stamp - a.stamp > self.max_gap:
                    self.stats.odom_gap += 1
                    continue
                pose = interpolate_pose(a, b, scan.stamp)
            self.stats.matched += 1
            out.append(Matched(scan, pose))
        self._forget()
        return out

    def _forget(self) -> None:
        stamps = self._stamps
        if not stamps:
            return
        cut = bisect.bisect_left(stamps, stamps[-1] - self.horizon)
        if self._last_scan is not None and not self._pending:
            # later scans have later stamps: the sample before the last scan's stamp is the oldest needed
            cut = max(cut, bisect.bisect_right(stamps, self._last_scan) - 1)
        elif self._pending:
            cut = min(cut, max(0, bisect.bisect_right(stamps, self._pending[0][0].stamp) - 1))
        cut = min(cut, len(stamps) - 1)
        if cut > 0:
            del stamps[:cut]
            del self._poses[:cut]
