"""A recording as a sensor source: one robot's scans and odometry, decoded, in arrival order.

:class:`RecordingFeed` is what :class:`~agent.core.sensor_loop.SensorLoop` is fed from a
recording by ``loci replay``, ``loci evaluate log``, ``loci people track``, the live agent
running on a recording (``[laser] source = "recording"``) and the benchmarks: the robot's
``scan`` and ``odom`` messages in file order (the recorder's arrival order), each a
:class:`~agent.core.sensor_loop.SensorMessage` whose arrival time is the recorded log time —
so the association's timeouts decide as they did live, however fast or slow the replay runs.
Iterate it plainly (as fast as the consumer goes, or paced at ``speed`` times recorded speed
with :func:`time.sleep`) or with ``async for`` (paced with :func:`asyncio.sleep`).

Messages that do not decode are counted (``invalid_scans``, ``invalid_odometry``) and left
out, as the live subscriptions do; scans stamped after ``until`` (the live run's last scan,
when the agent was stopping) are counted ``skipped``; with ``duration`` only the first
seconds of the recording are read. A file whose writer crashed is read up to its last
complete message (:attr:`RecordingFeed.truncated`).
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

from agent.bus.codecs import LASER_SCAN_CODEC, POSE_CODEC, checked_decode
from agent.bus.keys import RobotKeys
from agent.core.sensor_loop import SensorMessage
from agent.recording.replay import RecordedMessage, Replay
from knowledge.errors import DataError, ProtocolError

__all__ = ["RecordingFeed", "recording_robot"]


def recording_robot(path: Path, meta: dict[str, str], robot: str | None = None) -> str:
    """The robot whose messages to take: ``robot``, else the recording's metadata's, else the
    only robot with scans in the file.

    Raises:
        DataError: the file has scans of several robots (or none) and none was named.
    """
    from agent.recording.replay import McapMessages

    robot = robot or meta.get("robot")
    if robot:
        return robot
    topics = {m.topic for m in McapMessages(path)}
    robots = sorted({t.split("/")[1] for t in topics if t.startswith("loci/") and t.endswith("/scan")})
    if len(robots) != 1:
        raise DataError(f"{path}: name the robot with --robot (scans of: {', '.join(robots) or 'none'})")
    return robots[0]


class RecordingFeed:
    """One robot's scans and odometry in a recording (see the module docstring).

    Args:
        path: a loci MCAP recording (see :func:`~agent.recording.importer.as_loci_recording`
            for other formats).
        robot: whose messages (default: :func:`recording_robot`).
        meta: the recording's ``loci`` metadata, if the caller has read it.
        speed: None = as fast as the consumer takes them; 1.0 = recorded speed.
        until: scans stamped after this are skipped (counted).
        duration: read only this many seconds of the recording (from its first message).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        robot: str | None = None,
        meta: dict[str, str] | None = None,
        speed: float | None = None,
        until: float | None = None,
        duration: float | None = None,
    ) -> None:
        from agent.recording.offline import read_recording_metadata

        self.path = Path(path)
        self.meta = meta if meta is not None else read_recording_metadata(self.path)
        self.robot = recording_robot(self.path, self.meta, robot)
        self.keys = RobotKeys(self.robot)
        if duration is not None and not duration > 0:
            raise ValueError(f"duration must be > 0 seconds, got {duration}")
        self.speed = speed
        self.until = until
        self.duration = duration
        self._replay = Replay(self.path, speed=speed, topics={self.keys.scan, self.keys.odom})
        self._start_log: float | None = None
        self._start_clock: float | None = None
        #: messages read, scans and odometry among them, those that did not decode, scans after ``until``
        self.messages = 0
        self.scans = 0
        self.odometry = 0
        self.invalid_scans = 0
        self.invalid_odometry = 0
        self.skipped = 0
        #: the feed stopped at ``duration``
        self.cut = False

    @property
    def truncated(self) -> bool:
        """The file ended without its footer (its writer crashed)."""
        return self._replay.truncated

    def now(self) -> float:
        """The recording's clock now: the log time being replayed (paced feeds; else the last
        message's log time)."""
        if self._start_log is None or self._start_clock is None:
            return self._start_log or 0.0
        if self.speed is None:
            return self._last_log
        return self._start_log + (time.monotonic() - self._start_clock) * self.speed

    def _message(self, msg: RecordedMessage) -> SensorMessage | None:
        """The message decoded (None: left out, counted)."""
        log_time = msg.log_time_ns * 1e-9
        if self._start_log is None:
            self._start_log, self._start_clock = log_time, time.monotonic()
        self._last_log = log_time
        self.messages += 1
        if msg.topic == self.keys.odom:
            self.odometry += 1
            try:
                pose = checked_decode(POSE_CODEC, msg.zenoh_encoding, msg.data, msg.topic)
            except ProtocolError:
                self.invalid_odometry += 1
                return None
            return SensorMessage("odom", log_time, pose)
        self.scans += 1
        try:
            scan = checked_decode(LASER_SCAN_CODEC, msg.zenoh_encoding, msg.data, msg.topic)
        except ProtocolError:
            self.invalid_scans += 1
            return None
        if self.until is not None and scan.stamp > self.until:
            self.skipped += 1
            return None
        return SensorMessage("scan", log_time, scan)

    def _over(self, msg: RecordedMessage) -> bool:
        if self.duration is None or self._start_log is None:
            return False
        if msg.log_time_ns * 1e-9 - self._start_log > self.duration:
            self.cut = True
            return True
        return False

    def __iter__(self) -> Iterator[SensorMessage]:
        for msg in self._replay:
            if self._over(msg):
                return
            out = self._message(msg)
            if out is not None:
                yield out

    async def __aiter__(self) -> AsyncIterator[SensorMessage]:
        async for msg in self._replay:
            if self._over(msg):
                return
            out = self._message(msg)
            if out is not None:
                yield out

    _last_log = 0.0
