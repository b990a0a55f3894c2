"""Each scan with the odometry pose at the scan's stamp, whatever the real timing.

Scans and odometry come from different devices at different rates, and real stamps are
messy: they jitter, arrive late, repeat, or go backwards a little. :class:`OdomSync` gives
every scan the robot's odometry pose **at the scan's stamp**, interpolated between the two
odometry samples around it (position linearly, heading along the shorter arc), and hands
the scans on **in stamp order** (the local map and the people tracker run forwards in
time). A scan therefore waits until odometry newer than its stamp has arrived, for at most
``max_wait`` seconds of arrival time.

Why stamps and not arrival times: the pose then depends only on the scan and odometry
messages, never on when they happened to be delivered, so a live run and a replay of its
recording (:mod:`agent.recording.offline`) give every scan the same pose. The decisions that
depend on arrival times (the timeouts below) are taken with the recorded arrival times
(MCAP log times) in a replay, at the first message after the deadline, as live.

Waiting scans are kept sorted by stamp, so a scan that arrives after a newer one but
before that one is handed on takes its place in the order, and one scan stamped ahead of
its neighbours costs only itself. ``reorder`` (seconds, 0 by default) holds every scan
that long before it is handed on, so that scans arriving up to that late still find their
place (a replay of a log with jittered stamps; costs latency on a robot).

What happens to a scan (:class:`SyncStats`; the counters add up:
``scans == matched + dropped + pending``):

* **matched**: odometry newer than its stamp arrived in time; the pose is interpolated. Also
  matched, and counted in ``extrapolated`` as well: after ``max_wait`` without newer
  odometry, a scan at most ``max_extrapolation`` seconds past the newest sample gets the pose
  extrapolated from the last two samples (constant velocity).
* **no_odometry**: no odometry newer than its stamp within ``max_wait`` (odometry stopped or
  lags by more than ``max_extrapolation``): dropped. While odometry is stopped every scan is
  dropped this way, and counted; processing resumes by itself when odometry comes back.
* **odom_gap**: the two samples around it are more than ``max_gap`` apart and the robot
  moved between them (more than ``still`` metres or radians): dropped rather than
  interpolated across the break. Across a gap in which the robot stood still (a base that
  only reports motion), the pose is known and the scan is matched.
* **before_odometry**: its stamp is older than every odometry sample kept (the laser started
  before the base, or the scan is older than ``horizon``): dropped.
* **late**: its stamp is older than a scan already handed on (it arrived more than
  ``reorder`` too late to be put in order): dropped.
* **duplicate**: its stamp equals that of a scan waiting or handed on (a repeated message):
  dropped.
* **future_stamp**: stamped more than ``max_future`` seconds ahead of its arrival (a wrong
  clock, or a forged message): refused, so that one such scan cannot hold up the others.
* **overflow**: more than ``max_pending`` scans waiting: the oldest is dropped.
* **unfinished**: still waiting, with no odometry for it, when :meth:`OdomSync.close` is
  called (shutdown, end of a recording): dropped.

Odometry samples whose stamp is not after the newest one are ignored
(``odom_out_of_order``); samples stamped more than ``max_future`` ahead of their arrival are
refused (``odom_future``), so that one message cannot make every later sample look old.
Odometry older than the sample before the oldest scan still needed, or older than
``horizon`` seconds before the newest sample, is forgotten (decided by stamps, so replay
forgets the same samples).

Times: stamps and ``now`` are seconds since the Unix epoch (the same clock for odometry,
scans and arrival times, as on one host).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from drivers.messages import LaserScan, Pose2D

__all__ = ["DROP_REASONS", "Matched", "OdomSync", "SyncParams", "SyncStats", "interpolate_pose"]

#: The named reasons a scan is not handed on, in the order the summaries list them.
DROP_REASONS = (
    "no_odometry",
    "odom_gap",
    "before_odometry",
    "late",
    "duplicate",
    "future_stamp",
    "overflow",
    "unfinished",
)


@dataclass(frozen=True)
class SyncParams:
    """How :class:`OdomSync` associates scans with odometry (``[odometry]`` in the robot's
    configuration; see the module docstring for what each does to a scan).

    Attributes:
        max_wait: seconds (arrival time) a scan waits for odometry newer than its stamp.
        max_gap: seconds; the longest odometry interval a scan is interpolated across while
            the robot moves.
        still: metres (and radians) of motion across a longer gap below which the robot
            counts as standing still, and the scan is matched.
        max_extrapolation: seconds past the newest odometry sample a scan may be, after
            ``max_wait``, to get an extrapolated pose (0: never extrapolate).
        max_future: seconds a scan or odometry sample may be stamped ahead of its arrival.
        reorder: seconds (arrival time) every scan is held so that late scans find their
            place in stamp order (0: hand each scan on as soon as its odometry is there).
        horizon: seconds of odometry kept before the newest sample.
        max_pending: the most scans waiting at once.
    """

    max_wait: float = 0.2
    max_gap: float = 0.5
    still: float = 0.01
    max_extrapolation: float = 0.1
    max_future: float = 1.0
    reorder: float = 0.0
    horizon: float = 10.0
    max_pending: int = 256

    def __post_init__(self) -> None:
        for name in ("max_wait", "max_gap", "max_future", "horizon"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
        for name in ("still", "max_extrapolation", "reorder"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
        if isinstance(self.max_pending, bool) or not (
            isinstance(self.max_pending, int) and self.max_pending >= 1
        ):
            raise ValueError(f"max_pending must be an integer >= 1 (scans), got {self.max_pending!r}")

    def to_table(self) -> dict[str, Any]:
        """Plain values (stored in recordings, so a replay associates as the live run did)."""
        return asdict(self)

    @classmethod
    def from_table(cls, table: dict[str, Any]) -> SyncParams:
        """The inverse of :meth:`to_table`; unknown keys are ignored (a newer writer's)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in table.items() if k in names})


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
    extrapolated: int = 0
    no_odometry: int = 0
    odom_gap: int = 0
    before_odometry: int = 0
    late: int = 0
    duplicate: int = 0
    future_stamp: int = 0
    overflow: int = 0
    unfinished: int = 0
    odom: int = 0
    odom_out_of_order: int = 0
    odom_future: int = 0

    @property
    def dropped(self) -> int:
        """Scans that were not matched, for whatever reason."""
        return sum(getattr(self, name) for name in DROP_REASONS)

    def drops(self) -> dict[str, int]:
        """Reason → scans dropped for it (every reason, zeros included)."""
        return {name: getattr(self, name) for name in DROP_REASONS}

    def as_dict(self) -> dict[str, int]:
        return {**asdict(self), "dropped": self.dropped}


def interpolate_pose(a: Pose2D, b: Pose2D, stamp: float) -> Pose2D:
    """The pose at ``stamp`` on the line through ``a`` and ``b``: position linear in time,
    heading along the shorter arc. Between the two stamps it interpolates; beyond ``b`` it
    extrapolates at the same velocity."""
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


def _moved(a: Pose2D, b: Pose2D) -> float:
    """The larger of the distance (metres) and the turn (radians) from ``a`` to ``b``."""
    dth = abs(math.atan2(math.sin(b.theta - a.theta), math.cos(b.theta - a.theta)))
    return max(math.hypot(b.x - a.x, b.y - a.y), dth)


class OdomSync:
    """Associates scans with odometry by stamp (see the module docstring).

    Feed it in arrival order: :meth:`add_odom`, :meth:`add_scan` (each returns the scans
    handed on now, in stamp order) and :meth:`expire` when time passes without messages;
    :meth:`close` at the end.

    Args:
        params: the parameters (default :class:`SyncParams`); keyword arguments override
            single fields (``OdomSync(max_wait=0.5)``).
    """

    def __init__(self, params: SyncParams | None = None, **overrides: Any) -> None:
        base = params or SyncParams()
        self.params = SyncParams.from_table({**base.to_table(), **overrides}) if overrides else base
        unknown = set(overrides) - set(self.params.to_table())
        if unknown:
            raise TypeError(f"OdomSync: unknown parameter {sorted(unknown)[0]!r}")
        self.stats = SyncStats()
        self._stamps: list[float] = []
        self._poses: list[Pose2D] = []
        # waiting scans, sorted by (stamp, arrival number): (stamp, n, arrival time, scan)
        self._pending: list[tuple[float, int, float, LaserScan]] = []
        self._arrivals = 0
        self._last_out: float | None = None  # stamp of the last scan handed on
        self._now = -math.inf

    # the parameters read most, as attributes
    @property
    def max_wait(self) -> float:
        return self.params.max_wait

    @property
    def max_gap(self) -> float:
        return self.params.max_gap

    @property
    def pending(self) -> int:
        """Scans waiting for odometry (or for their ``reorder`` time)."""
        return len(self._pending)

    @property
    def buffered(self) -> int:
        """Odometry samples kept."""
        return len(self._stamps)

    @property
    def latest_odom(self) -> Pose2D | None:
        """The newest odometry sample."""
        return self._poses[-1] if self._poses else None

    # ------------------------------------------------------------------ input
    def expire(self, now: float) -> list[Matched]:
        """Time passed without messages: returns the scans handed on by ``now`` (held scans
        whose ``reorder`` time is over, extrapolated ones); drops those waiting in vain."""
        self._now = max(self._now, float(now))
        return self._release()

    def add_odom(self, pose: Pose2D, now: float) -> list[Matched]:
        """An odometry sample arrived at ``now``; returns the scans handed on now."""
        out = self.expire(now)
        if pose.stamp > float(now) + self.params.max_future or not math.isfinite(pose.stamp):
            self.stats.odom_future += 1
            return out
        if self._stamps and pose.stamp <= self._stamps[-1]:
            self.stats.odom_out_of_order += 1
            return out
        self.stats.odom += 1
        self._stamps.append(pose.stamp)
        self._poses.append(pose)
        out.extend(self._release())
        return out

    def add_scan(self, scan: LaserScan, now: float) -> list[Matched]:
        """A scan arrived at ``now``; returns the scans handed on now (this one, if its
        odometry is there and it is not held)."""
        out = self.expire(now)
        st = self.stats
        st.scans += 1
        stamp = float(scan.stamp)
        if not math.isfinite(stamp) or stamp > float(now) + self.params.max_future:
            st.future_stamp += 1
            return out
        if self._last_out is not None and stamp <= self._last_out:
            if stamp == self._last_out:
                st.duplicate += 1
            else:
                st.late += 1
            return out
        i = bisect.bisect_left(self._pending, (stamp, -1))
        if i < len(self._pending) and self._pending[i][0] == stamp:
            st.duplicate += 1
            return out
        self._arrivals += 1
        self._pending.insert(i, (stamp, self._arrivals, self._now, scan))
        if len(self._pending) > self.params.max_pending:
            self._pending.pop(0)
            st.overflow += 1
        out.extend(self._release())
        return out

    def close(self) -> list[Matched]:
        """The end (shutdown, end of a recording): hands on the waiting scans that odometry
        covers, or that may be extrapolated, without holding them; drops the rest
        (``unfinished``). Returns the scans handed on."""
        out = self._release(final=True)
        self.stats.unfinished += len(self._pending)
        self._pending.clear()
        return out

    # ------------------------------------------------------------------ release
    def _release(self, *, final: bool = False) -> list[Matched]:
        """Hand on the waiting scans in stamp order, as far as odometry and time allow."""
        prm = self.params
        st = self.stats
        out: list[Matched] = []
        while self._pending:
            stamp, _, arrived, scan = self._pending[0]
            waited = self._now - arrived
            if not final and waited < prm.reorder:
                break  # held: a late scan may still come before it
            pose: Pose2D | None = None
            if self._stamps and self._stamps[-1] >= stamp:
                pose = self._interpolate(stamp)
                if pose is None:  # dropped (before_odometry, odom_gap): counted
                    self._pending.pop(0)
                    continue
            elif final or waited > prm.max_wait + prm.reorder:
                pose = self._extrapolate(stamp)
                if pose is None:
                    if final:
                        break  # counted as unfinished by close()
                    self._pending.pop(0)
                    st.no_odometry += 1
                    continue
                st.extrapolated += 1
            else:
                break  # waits for newer odometry
            self._pending.pop(0)
            st.matched += 1
            self._last_out = stamp
            out.append(Matched(scan, pose))
        self._forget()
        return out

    def _interpolate(self, stamp: float) -> Pose2D | None:
        """The pose at ``stamp`` from the samples around it (None: dropped and counted)."""
        stamps = self._stamps
        i = bisect.bisect_right(stamps, stamp)
        if i == 0:
            self.stats.before_odometry += 1
            return None
        a = self._poses[i - 1]
        if a.stamp == stamp:
            return Pose2D(a.x, a.y, a.theta, stamp=stamp, frame_id=a.frame_id)
        b = self._poses[i]
        if b.stamp - a.stamp > self.params.max_gap and _moved(a, b) > self.params.still:
            self.stats.odom_gap += 1
            return None
        return interpolate_pose(a, b, stamp)

    def _extrapolate(self, stamp: float) -> Pose2D | None:
        """The pose at ``stamp`` past the newest sample, at most ``max_extrapolation`` ahead."""
        if not self._poses:
            return None
        b = self._poses[-1]
        if stamp - b.stamp > self.params.max_extrapolation:
            return None
        if len(self._poses) >= 2 and b.stamp - self._poses[-2].stamp <= self.params.max_gap:
            return interpolate_pose(self._poses[-2], b, stamp)
        return Pose2D(b.x, b.y, b.theta, stamp=stamp, frame_id=b.frame_id)

    def _forget(self) -> None:
        stamps = self._stamps
        if not stamps:
            return
        cut = bisect.bisect_left(stamps, stamps[-1] - self.params.horizon)
        # the oldest scan still to come is the first waiting one, else one after the last handed on
        oldest = self._pending[0][0] if self._pending else self._last_out
        if oldest is not None:
            need = max(0, bisect.bisect_right(stamps, oldest) - 1)
            cut = min(cut, need) if self._pending else max(cut, need)
        cut = min(cut, len(stamps) - 2)  # keep two samples: extrapolation needs a velocity
        if cut > 0:
            del stamps[:cut]
            del self._poses[:cut]
