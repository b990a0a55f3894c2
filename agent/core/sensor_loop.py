"""The one sensor loop: scans and odometry in, each scan with its pose through a step, in stamp order.

Every way the agent's chain runs — the robot live (``loci run``: the LMS driver, or scans
and odometry from the bus), a recording (``loci replay``, ``loci evaluate log``), people
tracked over a recording (``loci people track``), the benchmarks — feeds the same
:class:`SensorLoop`, as python-can's ``Notifier`` serves a live ``Bus`` and a
``LogReader`` alike. So what a replay measures is what the robot ran: the association of
scans with odometry (:class:`~agent.core.odom_sync.OdomSync`, by stamps; the arrival times
decide only the timeouts, and a recording carries them), the order (stamp order), what is
dropped and why (counted by the association, never by timing), which scans a slow computer
leaves out (``max_rate``: a rule on the scans' stamps, the same at any speed, counted
``over_rate``), and what a failing step costs (that scan only, counted).

Sources give :class:`SensorMessage` s in arrival order: the live runtime from its driver
thread and bus subscriptions, a recording from its file
(:class:`~agent.recording.feed.RecordingFeed`, arrival = the recorded log time). The loop is
synchronous and does no I/O; a step is any callable taking a
:class:`~agent.core.odom_sync.Matched` (usually ``Pipeline.process`` and what publishes its
result).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from agent.core.odom_sync import Matched, OdomSync, SyncParams
from drivers.messages import LaserScan, Pose2D

__all__ = ["SensorLoop", "SensorMessage"]

log = logging.getLogger(__name__)

#: ``max_rate``'s tolerance: a scan is stepped when this fraction of ``1 / max_rate`` passed
#: since the last one (stamps jitter; 0.9 keeps every second scan of an LMS at 37.5 Hz with a
#: limit of 20 Hz while the stamps jitter by up to 5 ms).
RATE_SLACK = 0.9

#: The kinds of :class:`SensorMessage`.
KINDS = ("scan", "odom")


@dataclass(frozen=True, slots=True)
class SensorMessage:
    """A scan or an odometry pose, and when it arrived (seconds on the source's clock: the
    host's for a live source, the recorded log time for a recording)."""

    kind: str
    arrival: float
    value: LaserScan | Pose2D


class SensorLoop:
    """Associates scans with odometry and runs ``step`` on each scan, in stamp order.

    Args:
        sync: the association (an :class:`OdomSync`, or its parameters).
        step: called with each matched scan; what it returns is ignored.
        on_error: called with the scan and the exception when ``step`` raises (the scan is
            skipped and counted in :attr:`errors`; default: logged, the first few with their
            traceback).
        max_rate: scans per second stepped at most (0: every scan). A matched scan is
            stepped when its stamp is at least ``RATE_SLACK / max_rate`` seconds after the
            last stepped scan's, else left out (counted in :attr:`over_rate`): an LMS at 37.5 Hz
            with ``max_rate = 20`` gives every second scan. The rule reads stamps only, so a
            replay at any speed and the live robot on any computer step the same scans.
        observe: called with each scan left out by ``max_rate`` instead of ``step`` (the
            pipeline's cheap part that needs every scan: ``Pipeline.observe``); a failure
            there is handled as one in ``step``.
    """

    def __init__(
        self,
        sync: OdomSync | SyncParams | None,
        step: Callable[[Matched], Any],
        *,
        on_error: Callable[[Matched, Exception], None] | None = None,
        max_rate: float = 0.0,
        observe: Callable[[Matched], Any] | None = None,
    ) -> None:
        if isinstance(max_rate, bool) or not (math.isfinite(max_rate) and max_rate >= 0):
            raise ValueError(f"max_rate must be scans per second >= 0 (0: every scan), got {max_rate!r}")
        self.sync = sync if isinstance(sync, OdomSync) else OdomSync(sync)
        self.step = step
        self.on_error = on_error
        self.max_rate = float(max_rate)
        self.observe = observe
        self._min_interval = RATE_SLACK / self.max_rate if self.max_rate else 0.0
        self._last_stamp: float | None = None
        #: scans and odometry poses fed; scans stepped; steps that raised
        self.scans = 0
        self.odometry = 0
        self.processed = 0
        self.errors = 0
        #: scans left out by ``max_rate``
        self.over_rate = 0

    # ------------------------------------------------------------------ input
    def feed(self, message: SensorMessage) -> int:
        """One message from a source; returns the scans stepped now."""
        if message.kind == "scan":
            assert isinstance(message.value, LaserScan)
            return self.scan(message.value, message.arrival)
        if message.kind == "odom":
            assert isinstance(message.value, Pose2D)
            return self.odom(message.value, message.arrival)
        raise ValueError(f"a sensor message is one of {KINDS}, got {message.kind!r}")

    def scan(self, scan: LaserScan, arrival: float) -> int:
        """A scan arrived; returns the scans stepped now."""
        self.scans += 1
        return self._run(self.sync.add_scan(scan, arrival))

    def odom(self, pose: Pose2D, arrival: float) -> int:
        """An odometry pose arrived; returns the scans stepped now."""
        self.odometry += 1
        return self._run(self.sync.add_odom(pose, arrival))

    def tick(self, now: float) -> int:
        """Time passed without messages (the source's clock); returns the scans stepped now."""
        return self._run(self.sync.expire(now))

    def close(self) -> int:
        """The source ended: the scans odometry covers are stepped, the rest dropped (counted)."""
        return self._run(self.sync.close())

    @property
    def pending(self) -> int:
        """Scans waiting for their odometry."""
        return self.sync.pending

    # ------------------------------------------------------------------ steps
    def _run(self, matched: list[Matched]) -> int:
        stepped = 0
        for m in matched:
            last = self._last_stamp
            over = bool(self._min_interval) and last is not None and m.scan.stamp - last < self._min_interval
            handler = self.observe if over else self.step
            if over:
                self.over_rate += 1
            else:
                self._last_stamp = m.scan.stamp
                stepped += 1
            if handler is None:
                continue
            try:
                handler(m)
            except Exception as exc:  # a bug or a strange scan: that scan is skipped, counted
                self.errors += 1
                if self.on_error is not None:
                    self.on_error(m, exc)
                elif self.errors <= 5:
                    log.exception(
                        "processing scan %d (stamp %.3f) failed; it is skipped", m.scan.seq, m.scan.stamp
                    )
                continue
            if not over:
                self.processed += 1
        return stepped
