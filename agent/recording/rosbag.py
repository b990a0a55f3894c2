"""ROS bags (ROS 1, ROS 2): deserialized messages in, typed scans and poses out (pure code).

The reading (``rosbags``) happens in :mod:`agent.recording.importer`; here are the rules:

* ``sensor_msgs/LaserScan`` → :class:`~drivers.messages.LaserScan` (:func:`scan_from_ros`):
  any beam count and field of view; a negative ``angle_increment`` (beams clockwise) is
  reversed into our counter-clockwise order; the ranges follow REP 117: +inf (no return) →
  ``range_max``, NaN and -inf (invalid, too close) → 0.0 (invalid), finite ranges above
  ``range_max`` → ``range_max``. A laser mounted upside down (its z axis pointing down in
  ``/tf``) has its beams mirrored.
* ``nav_msgs/Odometry`` → the base's pose in the odometry frame (:func:`pose_from_odometry`),
  or ``/tf``: the odometry frame → base frame transform each time one of its dynamic links
  is published (:class:`TfBuffer`).
* ``/tf_static`` and ``/tf``: the laser's mount on the base (base frame → laser frame,
  through any chain of frames), the first time the chain is complete.

Frame names lose a leading ``/`` (ROS 1's tf_prefix style: ``/odom`` is ``odom``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from agent.recording.imported import ODOM, SCAN, Outcome, Output, Skip, same_pose
from drivers.messages import LaserScan, Pose2D
from knowledge.errors import ConfigError

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF, TF_STATIC = "/tf", "/tf_static"


class BadMessage(ValueError):
    """A message with values no scan or pose can have; ``reason`` is its skip reason."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def frame(name: str) -> str:
    """A frame name without ROS 1's leading ``/``."""
    return name.lstrip("/")


def stamp_of(header: Any) -> float:
    """A ``std_msgs/Header`` stamp in seconds."""
    return float(header.stamp.sec) + float(header.stamp.nanosec) * 1e-9


def yaw_of(q: Any) -> float:
    """The rotation about z of a quaternion (``x, y, z, w``), rad."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


# ---- topics ------------------------------------------------------------------------------


def choose_topics(
    topics: Mapping[str, str], scan_topic: str | None = None, odom_topic: str | None = None
) -> tuple[str, str]:
    """``(scan topic, odometry topic or "/tf")`` of a bag's ``topic → message type``.

    Found by type unless named: the one ``sensor_msgs/LaserScan`` topic, the one
    ``nav_msgs/Odometry`` topic (else ``/tf``).

    Raises:
        ConfigError: a named topic is missing or of another type, or the choice is
            ambiguous or impossible (the message lists the candidates).
    """
    scans = sorted(t for t, ty in topics.items() if ty == LASER_SCAN)
    if scan_topic is not None:
        if topics.get(scan_topic) != LASER_SCAN:
            raise ConfigError(
                f"--scan-topic {scan_topic}: "
                + (f"is {topics[scan_topic]}, not {LASER_SCAN}" if scan_topic in topics else "not in the bag")
                + f"; LaserScan topics: {', '.join(scans) or 'none'}"
            )
    elif len(scans) == 1:
        scan_topic = scans[0]
    else:
        raise ConfigError(
            "the bag has no sensor_msgs/LaserScan topic"
            if not scans
            else f"the bag has {len(scans)} sensor_msgs/LaserScan topics ({', '.join(scans)}): "
            "choose one with --scan-topic"
        )
    odoms = sorted(t for t, ty in topics.items() if ty == ODOMETRY)
    has_tf = topics.get(TF) == TF_MESSAGE
    if odom_topic is not None:
        if odom_topic == TF:
            if not has_tf:
                raise ConfigError(f"--odom-topic /tf: the bag has no {TF} ({TF_MESSAGE}) topic")
        elif topics.get(odom_topic) != ODOMETRY:
            raise ConfigError(
                f"--odom-topic {odom_topic}: "
                + (f"is {topics[odom_topic]}, not {ODOMETRY}" if odom_topic in topics else "not in the bag")
                + f"; Odometry topics: {', '.join(odoms) or 'none'}"
                + ("; or /tf" if has_tf else "")
            )
    elif len(odoms) == 1:
        odom_topic = odoms[0]
    elif len(odoms) > 1:
        raise ConfigError(
            f"the bag has {len(odoms)} nav_msgs/Odometry topics ({', '.join(odoms)}): choose one with "
            "--odom-topic" + (" (or --odom-topic /tf)" if has_tf else "")
        )
    elif has_tf:
        odom_topic = TF
    else:
        raise ConfigError("the bag has neither a nav_msgs/Odometry topic nor /tf: no odometry to import")
    return scan_topic, odom_topic


# ---- transforms ----------------------------------------------------------------------------


Link = tuple[float, float, float, float, float, float, float]  # translation x y z, quaternion x y z w


def _link(t: Any) -> Link:
    """A ``geometry_msgs/Transform`` as 7 numbers (the quaternion normalised).

    Raises:
        BadMessage: a quaternion of zero or non-finite length, or a non-finite translation.
    """
    q, v = t.rotation, t.translation
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    tx, ty, tz = float(v.x), float(v.y), float(v.z)
    if not (math.isfinite(norm) and norm > 0 and all(math.isfinite(c) for c in (tx, ty, tz))):
        raise BadMessage("bad_message", f"transform ({tx}, {ty}, {tz}) with quaternion ({x}, {y}, {z}, {w})")
    return (tx, ty, tz, x / norm, y / norm, z / norm, w / norm)


def _matrix(link: Link) -> np.ndarray:
    """A link as a 4×4 matrix."""
    tx, ty, tz, x, y, z, w = link
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = [tx, ty, tz]
    return m


@dataclass(frozen=True)
class Mount:
    """The laser's pose on the base: ``(x m, y m, yaw rad)``; ``flipped``: upside down."""

    pose: tuple[float, float, float]
    flipped: bool = False


class TfBuffer:
    """The newest transform of every link of the tf tree (child → (parent, link, stamp))."""

    def __init__(self) -> None:
        self.links: dict[str, tuple[str, Link, float]] = {}

    def add(self, message: Any) -> list[tuple[str, str, float]]:
        """Add a ``tf2_msgs/TFMessage``; returns its links ``(parent, child, stamp)``."""
        added = []
        for t in message.transforms:
            parent, child = frame(t.header.frame_id), frame(t.child_frame_id)
            if not parent or not child or parent == child:
                continue
            stamp = stamp_of(t.header)
            self.links[child] = (parent, _link(t.transform), stamp)
            added.append((parent, child, stamp))
        return added

    def _to_root(self, name: str) -> list[str]:
        chain = [name]
        while chain[-1] in self.links and len(chain) < 64:
            parent = self.links[chain[-1]][0]
            if parent in chain:
                break
            chain.append(parent)
        return chain

    def path(self, parent: str, child: str) -> list[str] | None:
        """The frames from ``child`` up to ``parent`` (both included) when ``parent`` is an
        ancestor of ``child``, else None."""
        chain = self._to_root(child)
        return chain[: chain.index(parent) + 1] if parent in chain else None

    def lookup(self, parent: str, child: str) -> np.ndarray | None:
        """``parent → child`` as a 4×4 matrix (the pose of ``child`` in ``parent``), through
        their common ancestor; None when they are not connected."""
        up_child, up_parent = self._to_root(child), self._to_root(parent)
        common = next((f for f in up_child if f in up_parent), None)
        if common is None:
            return None

        def to_common(chain: list[str]) -> np.ndarray:
            m = np.eye(4)
            for f in chain[: chain.index(common)]:
                m = _matrix(self.links[f][1]) @ m
            return m

        return np.linalg.inv(to_common(up_parent)) @ to_common(up_child)

    def mount(self, base: str, laser: str) -> Mount | None:
        """The laser's :class:`Mount` on the base, or None when the tree does not connect them."""
        m = self.lookup(base, laser)
        if m is None:
            return None
        yaw = math.atan2(m[1, 0], m[0, 0])
        return Mount((float(m[0, 3]), float(m[1, 3]), yaw), flipped=bool(m[2, 2] < 0))

    def pose2d(self, parent: str, child: str, stamp: float) -> Pose2D | None:
        """The planar pose of ``child`` in ``parent`` (None when not connected)."""
        m = self.lookup(parent, child)
        if m is None:
            return None
        return Pose2D(
            float(m[0, 3]), float(m[1, 3]), math.atan2(m[1, 0], m[0, 0]), stamp=stamp, frame_id="odom"
        )


# ---- messages ------------------------------------------------------------------------------


def scan_from_ros(msg: Any, seq: int, *, flipped: bool = False, frame_id: str | None = None) -> LaserScan:
    """A ``sensor_msgs/LaserScan`` as our :class:`LaserScan` (see the module docstring).

    Raises:
        BadMessage: no beams (``zero_beams``), or an angle increment or ``range_max`` that is
            zero or not finite (``bad_message``).
    """
    r = np.asarray(msg.ranges, dtype=np.float64).copy()
    n = r.shape[0]
    if n == 0:
        raise BadMessage("zero_beams", "LaserScan with 0 ranges")
    inc = float(msg.angle_increment)
    angle_min = float(msg.angle_min)
    range_max = float(msg.range_max)
    range_min = float(msg.range_min)
    if not (math.isfinite(inc) and (inc != 0 or n == 1)) or not math.isfinite(angle_min):
        raise BadMessage("bad_message", f"LaserScan with angle_min {angle_min}, angle_increment {inc}")
    if not (math.isfinite(range_max) and range_max > 0):
        raise BadMessage("bad_message", f"LaserScan with range_max {range_max}")
    if not (math.isfinite(range_min) and range_min >= 0):
        range_min = 0.0
    given = np.asarray(msg.intensities, dtype=np.float64)
    intens: np.ndarray | None = given.copy() if given.shape == (n,) else None
    with np.errstate(invalid="ignore"):
        no_return = np.isposinf(r) | (np.isfinite(r) & (r > range_max))
        invalid = np.isnan(r) | np.isneginf(r)
    r[no_return] = range_max
    r[invalid] = 0.0
    if inc == 0:
        inc = 2 * math.pi  # one beam: any positive increment describes it
    if inc < 0:  # clockwise beams: reverse into counter-clockwise order
        angle_min, inc = angle_min + (n - 1) * inc, -inc
        r = r[::-1].copy()
        intens = None if intens is None else intens[::-1].copy()
    if flipped:  # upside down: beam at a in the laser is at -a about the base's z
        angle_min = -(angle_min + (n - 1) * inc)
        r = r[::-1].copy()
        intens = None if intens is None else intens[::-1].copy()
    return LaserScan(
        stamp=stamp_of(msg.header),
        seq=seq,
        frame_id=frame_id or frame(msg.header.frame_id) or "laser",
        angle_min=angle_min,
        angle_increment=inc,
        range_max=range_max,
        ranges=r,
        intensities=intens,
        range_min=range_min,
        scan_time=float(msg.scan_time) if math.isfinite(float(msg.scan_time)) else 0.0,
    )


def pose_from_odometry(msg: Any) -> Pose2D:
    """A ``nav_msgs/Odometry`` as the base's planar pose in the odometry frame.

    Raises:
        BadMessage: a position or orientation that is not finite.
    """
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    x, y, yaw = float(p.x), float(p.y), yaw_of(q)
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise BadMessage("bad_message", f"Odometry pose ({x}, {y}, yaw {yaw}) is not finite")
    return Pose2D(x, y, yaw, stamp=stamp_of(msg.header), frame_id="odom")


@dataclass(frozen=True)
class RosOptions:
    """How to read a bag (the ``loci import`` options).

    Attributes:
        scan_topic, odom_topic: the topics (None: found by type; odometry may be ``/tf``).
        laser_frame: the laser's frame for the mount (default: the scans' ``frame_id``).
        base_frame: the robot's base (default: the Odometry's ``child_frame_id``, else
            ``base_link``).
        odom_frame: the odometry frame for ``/tf`` odometry (default: the Odometry's
            ``frame_id``, else ``odom``).
        mount: the laser's mount (x, y, yaw) instead of the one in ``/tf``.
    """

    scan_topic: str | None = None
    odom_topic: str | None = None
    laser_frame: str | None = None
    base_frame: str | None = None
    odom_frame: str | None = None
    mount: tuple[float, float, float] | None = None


class RosConverter:
    """Turns a bag's messages into scans and odometry (after the mount is known).

    Args:
        scan_topic, odom_topic: as chosen by :func:`choose_topics`.
        base_frame, odom_frame: the frames of ``/tf`` odometry.
        mount: the laser's mount (only ``flipped`` matters here: the pose goes in the metadata).
        tf: the transform buffer (shared with the mount's look-up).
        warn: ``warn(reason, text)`` for messages imported with a warning.
    """

    def __init__(
        self,
        scan_topic: str,
        odom_topic: str,
        *,
        base_frame: str,
        odom_frame: str,
        mount: Mount,
        laser_frame: str | None = None,
        tf: TfBuffer | None = None,
        warn: Callable[[str, str], None] | None = None,
    ) -> None:
        self.scan_topic = scan_topic
        self.laser_frame = laser_frame
        self.odom_topic = odom_topic
        self.base_frame = base_frame
        self.odom_frame = odom_frame
        self.mount = mount
        self.tf = tf or TfBuffer()
        self.warn = warn or (lambda reason, text: None)
        self.notes: dict[str, int] = {}
        self._seq = 0
        self._last: dict[str, float] = {}
        self._odom_links: set[str] | None = None

    def topics(self) -> set[str]:
        """The topics it reads."""
        return {self.scan_topic, self.odom_topic, TF, TF_STATIC}

    def convert(self, index: int, topic: str, log_time: float, msg: Any) -> Outcome:
        """The outputs of message ``index`` (1-based, in bag order) on ``topic``."""
        try:
            if topic == self.scan_topic:
                self._seq += 1
                scan = scan_from_ros(msg, self._seq, flipped=self.mount.flipped)
                return self._checked(index, [Output(SCAN, scan, log_time)])
            if topic in (TF, TF_STATIC):
                return self._tf(index, topic, log_time, msg)
            if topic == self.odom_topic:
                return self._checked(index, [Output(ODOM, pose_from_odometry(msg), log_time)])
        except BadMessage as exc:
            return Skip(exc.reason, f"message {index} on {topic}: {exc}")
        except ValueError as exc:  # a value our message types refuse
            return Skip("bad_message", f"message {index} on {topic}: {exc}")
        return Skip("other_topic")

    def _tf(self, index: int, topic: str, log_time: float, msg: Any) -> Outcome:
        links = self.tf.add(msg)
        if self.laser_frame is not None and any(child == self.laser_frame for _, child, _ in links):
            now = self.tf.mount(self.base_frame, self.laser_frame)
            if now is not None and not same_pose(now.pose, self.mount.pose, 0.01):
                self.notes["mount_changed"] = self.notes.get("mount_changed", 0) + 1
                self.warn(
                    "mount_changed",
                    f"message {index} on {topic}: the laser's mount is now "
                    f"({now.pose[0]:.3f}, {now.pose[1]:.3f}, {math.degrees(now.pose[2]):.1f}°), "
                    f"not ({self.mount.pose[0]:.3f}, {self.mount.pose[1]:.3f}, "
                    f"{math.degrees(self.mount.pose[2]):.1f}°); the first one is used",
                )
        if self.odom_topic != TF or topic != TF:
            return Skip("tf_used")
        chain = self.tf.path(self.odom_frame, self.base_frame)
        if chain is None:
            return Skip("tf_used")
        on_chain = set(chain[:-1])
        stamps = [s for parent, child, s in links if child in on_chain]
        if not stamps:
            return Skip("tf_used")
        pose = self.tf.pose2d(self.odom_frame, self.base_frame, max(stamps))
        assert pose is not None
        return self._checked(index, [Output(ODOM, pose, log_time)])

    def _checked(self, index: int, outs: list[Output]) -> list[Output]:
        for out in outs:
            last = self._last.get(out.stream)
            stamp = out.message.stamp
            if last is not None and stamp <= last:
                self.notes["stamp_not_increasing"] = self.notes.get("stamp_not_increasing", 0) + 1
                self.warn(
                    "stamp_not_increasing",
                    f"message {index}: {out.stream} stamp {stamp:.6f} is not after the previous one "
                    f"({last:.6f}); imported as recorded",
                )
            self._last[out.stream] = stamp if last is None else max(stamp, last)
        return outs
