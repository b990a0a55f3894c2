"""Odometry: exact differential-drive dead reckoning and an async source of poses.

The core is pure functions on ``(x, y, theta)`` (metres, metres, radians), testable without
asyncio:

* :func:`arc_step` moves a pose along a circular arc of length ``ds`` that turns the heading
  by ``dtheta`` — the exact solution for constant (v, ω) over a step, not an Euler step.
* :func:`twist_step` / :func:`integrate_twists` integrate velocity commands.
* :class:`DiffDriveGeometry` turns wheel encoder ticks into arcs; :func:`integrate_ticks`
  integrates a sequence of absolute tick counts (with counter wrap-around).

:class:`OdometrySource` is the base class of everything that reports poses (a real base, the
simulated base, a replay): ``recv()`` with a timeout, ``latest()``, and async iteration.
:class:`TwistOdometry` and :class:`TickOdometry` are dead-reckoning sources fed by commands
or by wheel ticks.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from drivers.messages import Pose2D, Twist2D
from knowledge.errors import DeviceError, DeviceTimeout

#: A scalar or an array of them (the wheel/body conversions work element-wise on both).
Num = TypeVar("Num", float, np.ndarray)

#: Below this heading change (radians) an arc is treated as a straight line (series expansion).
_SMALL_ANGLE = 1e-6


def normalize_angle(a: float) -> float:
    """``a`` wrapped to (-π, π]."""
    return math.atan2(math.sin(a), math.cos(a))


def _sinc_terms(dtheta: float) -> tuple[float, float]:
    """``(sin(dθ)/dθ, (1 - cos(dθ))/dθ)``, exact near 0 by their Taylor series."""
    if abs(dtheta) < _SMALL_ANGLE:
        return 1.0 - dtheta * dtheta / 6.0, dtheta / 2.0
    # 1 - cos(x) = 2 sin²(x/2) avoids the cancellation that loses digits for small x
    return math.sin(dtheta) / dtheta, 2.0 * math.sin(dtheta / 2.0) ** 2 / dtheta


def arc_step(pose: tuple[float, float, float], ds: float, dtheta: float) -> tuple[float, float, float]:
    """Move ``pose = (x, y, theta)`` along an arc of length ``ds`` (m) turning by ``dtheta`` (rad).

    The arc starts tangent to the heading; ``ds < 0`` drives backwards. With ``ds = 0`` it is
    a rotation in place. The returned heading is wrapped to (-π, π].
    """
    x, y, th = pose
    a, b = _sinc_terms(dtheta)
    # displacement in the start frame: (ds·sin dθ/dθ, ds·(1 - cos dθ)/dθ), rotated by θ
    fx, fy = ds * a, ds * b
    c, s = math.cos(th), math.sin(th)
    return (x + c * fx - s * fy, y + s * fx + c * fy, normalize_angle(th + dtheta))


def twist_step(
    pose: tuple[float, float, float], v: float, omega: float, dt: float
) -> tuple[float, float, float]:
    """Integrate a constant velocity ``v`` (m/s), ``omega`` (rad/s) for ``dt`` seconds, exactly."""
    return arc_step(pose, v * dt, omega * dt)


def integrate_twists(
    start: tuple[float, float, float], v: np.ndarray, omega: np.ndarray, dt: np.ndarray | float
) -> np.ndarray:
    """Integrate piecewise-constant velocities; returns the ``(n + 1, 3)`` trajectory.

    ``v``, ``omega`` are ``(n,)`` arrays (m/s, rad/s) held for ``dt`` seconds each (scalar or
    ``(n,)``). Row 0 is ``start``; headings are not wrapped (they accumulate), so the
    result can be compared with closed forms directly.
    """
    v = np.asarray(v, dtype=np.float64).ravel()
    omega = np.asarray(omega, dtype=np.float64).ravel()
    if v.shape != omega.shape:
        raise ValueError(f"v {v.shape} and omega {omega.shape} must have the same length")
    dts = np.broadcast_to(np.asarray(dt, dtype=np.float64), v.shape)
    ds, dth = v * dts, omega * dts
    theta = start[2] + np.concatenate([[0.0], np.cumsum(dth)])
    small = np.abs(dth) < _SMALL_ANGLE
    safe = np.where(small, 1.0, dth)
    a = np.where(small, 1.0 - dth * dth / 6.0, np.sin(dth) / safe)
    b = np.where(small, dth / 2.0, 2.0 * np.sin(dth / 2.0) ** 2 / safe)
    fx, fy = ds * a, ds * b
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    x = start[0] + np.concatenate([[0.0], np.cumsum(c * fx - s * fy)])
    y = start[1] + np.concatenate([[0.0], np.cumsum(s * fx + c * fy)])
    return np.stack([x, y, theta], axis=1)


def tick_delta(previous: int, current: int, bits: int | None = None) -> int:
    """Signed difference of two encoder counts; with ``bits``, a counter that wraps at ``2**bits``.

    The shorter way round is taken, so a wrapping counter must be read at least twice per
    half revolution of its range.
    """
    d = int(current) - int(previous)
    if bits is None:
        return d
    if bits <= 0:
        raise ValueError(f"bits must be a positive counter width, got {bits}")
    m = 1 << bits
    d %= m
    return d - m if d >= m // 2 else d


@dataclass(frozen=True)
class DiffDriveGeometry:
    """A differential-drive base.

    Attributes:
        wheel_radius: metres.
        wheel_base: distance between the two wheels' contact points, metres.
        ticks_per_rev: encoder ticks per wheel revolution (after any gearbox).
    """

    wheel_radius: float
    wheel_base: float
    ticks_per_rev: float = 1.0

    def __post_init__(self) -> None:
        for name in ("wheel_radius", "wheel_base", "ticks_per_rev"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val > 0):
                raise ValueError(f"DiffDriveGeometry.{name} must be a positive number, got {val}")

    @property
    def metres_per_tick(self) -> float:
        return 2.0 * math.pi * self.wheel_radius / self.ticks_per_rev

    def ticks_to_arc(self, d_left: Num, d_right: Num) -> tuple[Num, Num]:
        """Tick increments of the left and right wheels → ``(ds, dtheta)`` (m, rad)."""
        sl, sr = d_left * self.metres_per_tick, d_right * self.metres_per_tick
        return (sl + sr) / 2.0, (sr - sl) / self.wheel_base

    def arc_to_ticks(self, ds: Num, dtheta: Num) -> tuple[Num, Num]:
        """Inverse of :meth:`ticks_to_arc`: the (fractional) tick increments that drive an arc."""
        half = dtheta * self.wheel_base / 2.0
        return (ds - half) / self.metres_per_tick, (ds + half) / self.metres_per_tick

    def wheel_speeds(self, v: Num, omega: Num) -> tuple[Num, Num]:
        """Left and right wheel angular speeds (rad/s) for a body velocity (m/s, rad/s)."""
        half = omega * self.wheel_base / 2.0
        return (v - half) / self.wheel_radius, (v + half) / self.wheel_radius

    def body_twist(self, left: Num, right: Num) -> tuple[Num, Num]:
        """Body velocity ``(v, omega)`` from wheel angular speeds (rad/s)."""
        vl, vr = left * self.wheel_radius, right * self.wheel_radius
        return (vl + vr) / 2.0, (vr - vl) / self.wheel_base


def integrate_ticks(
    start: tuple[float, float, float],
    left: Sequence[int] | np.ndarray,
    right: Sequence[int] | np.ndarray,
    geometry: DiffDriveGeometry,
    bits: int | None = None,
) -> np.ndarray:
    """Integrate absolute encoder counts ``left[k]``, ``right[k]``; returns ``(n, 3)`` poses.

    Row 0 is ``start`` (at the first reading); each later row applies the arc between two
    consecutive readings. Headings accumulate (not wrapped). ``bits`` handles counter wrap.
    """
    lt, rt = list(left), list(right)
    if len(lt) != len(rt) or not lt:
        raise ValueError(f"need equally many left and right readings (>= 1), got {len(lt)} and {len(rt)}")
    out = np.empty((len(lt), 3))
    out[0] = start
    x, y, th = start
    for k in range(1, len(lt)):
        ds, dth = geometry.ticks_to_arc(
            tick_delta(lt[k - 1], lt[k], bits), tick_delta(rt[k - 1], rt[k], bits)
        )
        nx, ny, _ = arc_step((x, y, th), ds, dth)
        x, y, th = nx, ny, th + dth
        out[k] = (x, y, th)
    return out


# ---------------------------------------------------------------------------------------- sources
class OdometrySource:
    """Base class of pose sources: ``await recv(timeout)``, ``latest()``, ``async for pose in src``.

    Backends either push poses with :meth:`_publish` (from the event loop's thread) or
    override :meth:`_recv_internal`. The queue keeps the newest ``queue_size`` poses and
    drops the oldest when a consumer is slow (``drops`` counts them); :meth:`latest` always
    has the newest. One consumer per source.
    """

    def __init__(self, *, frame_id: str = "odom", queue_size: int = 64) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size must be >= 1, got {queue_size}")
        self.frame_id = frame_id
        self.queue_size = queue_size
        self._poses: deque[Pose2D] = deque()
        self._wakeup = asyncio.Event()
        self._latest: Pose2D | None = None
        self._closed = False
        self.published = 0
        self.drops = 0

    def latest(self) -> Pose2D | None:
        """The newest pose, or None before the first one."""
        return self._latest

    def _publish(self, pose: Pose2D) -> None:
        if self._closed:
            return
        if len(self._poses) >= self.queue_size:
            self._poses.popleft()
            self.drops += 1
        self._poses.append(pose)
        self._latest = pose
        self.published += 1
        self._wakeup.set()

    async def _recv_internal(self) -> Pose2D | None:
        """The next pose, or None once the source is closed and drained."""
        while not self._poses:
            if self._closed:
                return None
            self._wakeup.clear()
            await self._wakeup.wait()
        return self._poses.popleft()

    async def recv(self, timeout: float | None = None) -> Pose2D:
        """The next pose. Raises DeviceTimeout after ``timeout`` s, DeviceError once closed."""
        try:
            pose = await asyncio.wait_for(self._recv_internal(), timeout)
        except TimeoutError as exc:
            raise DeviceTimeout(f"no odometry from {type(self).__name__} within {timeout} s") from exc
        if pose is None:
            raise DeviceError(f"{type(self).__name__} is closed; no more poses")
        return pose

    def __aiter__(self) -> OdometrySource:
        return self

    async def __anext__(self) -> Pose2D:
        pose = await self._recv_internal()
        if pose is None:
            raise StopAsyncIteration
        return pose

    async def close(self) -> None:
        """Stop the source; waiting consumers get the poses left, then the end."""
        self._closed = True
        self._wakeup.set()


class TwistOdometry(OdometrySource):
    """Dead reckoning from velocity commands (or measured twists), integrated exactly.

    ``command(twist)`` integrates the previous twist up to ``twist.stamp`` and then holds the
    new one; ``advance(stamp)`` integrates up to ``stamp`` and publishes a pose.
    """

    def __init__(self, start: Pose2D, *, queue_size: int = 64) -> None:
        super().__init__(frame_id=start.frame_id, queue_size=queue_size)
        self._pose = (start.x, start.y, start.theta)
        self._stamp = start.stamp
        self._twist = Twist2D(0.0, 0.0, start.stamp)
        self._latest = start

    def command(self, twist: Twist2D) -> Pose2D:
        """Integrate up to ``twist.stamp`` with the old velocity, then hold ``twist``."""
        pose = self.advance(twist.stamp)
        self._twist = twist
        return pose

    def advance(self, stamp: float) -> Pose2D:
        """Integrate the held velocity up to ``stamp`` (s) and publish the pose."""
        dt = stamp - self._stamp
        if dt < 0:
            raise ValueError(f"odometry time went backwards: {stamp} < {self._stamp}")
        self._pose = twist_step(self._pose, self._twist.v, self._twist.omega, dt)
        self._stamp = stamp
        pose = Pose2D(*self._pose, stamp=stamp, frame_id=self.frame_id)
        self._publish(pose)
        return pose


class TickOdometry(OdometrySource):
    """Dead reckoning for bases that report only wheel encoder counts.

    Feed absolute counts with :meth:`feed`; the first reading sets the reference.
    """

    def __init__(
        self,
        geometry: DiffDriveGeometry,
        start: Pose2D,
        *,
        bits: int | None = None,
        queue_size: int = 64,
    ) -> None:
        super().__init__(frame_id=start.frame_id, queue_size=queue_size)
        self.geometry = geometry
        self.bits = bits
        self._pose = (start.x, start.y, start.theta)
        self._last: tuple[int, int] | None = None
        self._latest = start

    def feed(self, left: int, right: int, stamp: float) -> Pose2D:
        """Absolute left/right counts read at ``stamp`` (s) → the new pose (also published)."""
        if self._last is not None:
            ds, dth = self.geometry.ticks_to_arc(
                tick_delta(self._last[0], left, self.bits), tick_delta(self._last[1], right, self.bits)
            )
            self._pose = arc_step(self._pose, ds, dth)
        self._last = (int(left), int(right))
        pose = Pose2D(*self._pose, stamp=stamp, frame_id=self.frame_id)
        self._publish(pose)
        return pose
