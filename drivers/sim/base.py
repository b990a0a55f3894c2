"""The simulated base: a differential drive that follows velocity or goal commands in a world.

:class:`SimBase` is a step-based core (``step(dt)``, deterministic for a seed and a sequence
of steps): it ramps towards the commanded velocity within acceleration and velocity limits,
integrates the TRUE pose exactly (arcs) in the world's frame, stops when its circular
footprint would touch an occupied cell, and reports ODOMETRY integrated from noisy
increments, which drifts away from the true pose as a real base's does.

Goals are reached by a turn-then-drive controller: turn in place while the heading error
is large, otherwise drive along a pure-pursuit arc to the current waypoint, slowing down so
as to stop on the final one, then turn to the goal heading.

:class:`SimBaseRunner` steps a base from asyncio — in real time or as fast as possible —
and publishes the odometry as an :class:`~drivers.odometry.OdometrySource`.
"""

from __future__ import annotations

import asyncio
import enum
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from drivers.messages import Pose2D, Twist2D
from drivers.odometry import OdometrySource, arc_step, normalize_angle
from knowledge.errors import DeviceTimeout
from knowledge.metric.grid import OccupancyGrid

log = logging.getLogger(__name__)


class Terrain(Protocol):
    """What the base collides with (:class:`sim.world.SimWorld`): the walls' grid, and the
    distance from points to the nearest wall."""

    @property
    def grid(self) -> OccupancyGrid: ...

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """Metres from world points ``(..., 2)`` to the nearest occupied cell (0 inside one)."""
        ...


@dataclass(frozen=True)
class BaseLimits:
    """Velocity (m/s, rad/s) and acceleration (m/s², rad/s²) limits."""

    v_max: float = 0.6
    omega_max: float = 1.5
    accel: float = 0.8
    alpha: float = 3.0

    def __post_init__(self) -> None:
        for name in ("v_max", "omega_max", "accel", "alpha"):
            if not getattr(self, name) > 0:
                raise ValueError(f"BaseLimits.{name} must be > 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class OdometryNoise:
    """Random-walk odometry errors, independent of the step size.

    Over a drive of ``d`` metres and a turn of ``a`` radians the odometry's distance error
    has standard deviation ``dist_std·√d`` and its heading error
    ``√(turn_std²·a + drift_std²·d)``.

    Attributes:
        dist_std: metres per √metre driven.
        turn_std: radians per √radian turned.
        drift_std: radians of heading per √metre driven.
    """

    dist_std: float = 0.02
    turn_std: float = 0.02
    drift_std: float = 0.01

    def __post_init__(self) -> None:
        if min(self.dist_std, self.turn_std, self.drift_std) < 0:
            raise ValueError("odometry noise standard deviations must be >= 0")


@dataclass(frozen=True)
class ControllerParams:
    """The goal controller's tolerances and gains.

    Attributes:
        goal_tolerance: metres from the final goal that count as reached.
        yaw_tolerance: radians of heading error that count as aligned at the goal.
        waypoint_tolerance: metres from an intermediate waypoint to move on to the next.
        turn_threshold: heading errors above this (radians) are turned away in place.
        k_omega: rad/s of turn rate per radian of heading error.
        k_v: 1/s: speed near the goal is at most ``k_v`` times the distance.
    """

    goal_tolerance: float = 0.05
    yaw_tolerance: float = 0.05
    waypoint_tolerance: float = 0.2
    turn_threshold: float = 0.6
    k_omega: float = 2.5
    k_v: float = 1.5


class BaseStatus(enum.Enum):
    """What the base is doing."""

    IDLE = "idle"
    VELOCITY = "velocity"
    GOAL = "goal"
    REACHED = "reached"
    COLLIDED = "collided"


@dataclass(frozen=True)
class BaseState:
    """The outcome of one step.

    Attributes:
        time: simulated seconds since the base was made.
        true_pose: where the base really is (world frame ``"map"``).
        odom: where its odometry says it is (frame ``"odom"``).
        twist: the velocity actually driven during the step.
        status: what it is doing now.
        event: what happened in this step ("goal reached", "collision ..."), or None.
    """

    time: float
    true_pose: Pose2D
    odom: Pose2D
    twist: Twist2D
    status: BaseStatus
    event: str | None = None


_Target = tuple[float, float, float | None]


class SimBase:
    """A simulated differential-drive base (see the module docstring).

    Args:
        world: walls to collide with (None: an empty plane).
        start: the true start pose (world frame).
        radius: the footprint's radius, metres.
        limits, noise, control: see :class:`BaseLimits`, :class:`OdometryNoise`, :class:`ControllerParams`.
        seed: seeds the odometry noise.
        odom_start: the odometry's start pose (default: the true start pose, so that
            ``odom - true`` is the drift).
        stamp_origin: epoch seconds of simulated time 0 (the poses' stamps are
            ``stamp_origin + time``).
        cmd_timeout: a velocity command older than this (s) is replaced by a stop (None: never).
    """

    def __init__(
        self,
        world: Terrain | None,
        start: Pose2D,
        *,
        radius: float = 0.2,
        limits: BaseLimits | None = None,
        noise: OdometryNoise | None = None,
        control: ControllerParams | None = None,
        seed: int = 0,
        odom_start: Pose2D | None = None,
        stamp_origin: float = 0.0,
        cmd_timeout: float | None = None,
    ) -> None:
        if radius < 0:
            raise ValueError(f"radius must be >= 0 metres, got {radius}")
        self.world = world
        self.radius = radius
        self.limits = limits or BaseLimits()
        self.noise = noise if noise is not None else OdometryNoise()
        self.control = control or ControllerParams()
        self.cmd_timeout = cmd_timeout
        self.stamp_origin = stamp_origin
        self._rng = np.random.default_rng(seed)
        self._true = (start.x, start.y, start.theta)
        o = odom_start or start
        self._odom = (o.x, o.y, o.theta)
        self._time = 0.0
        self._v = 0.0
        self._omega = 0.0
        self._cmd: Twist2D | None = None
        self._cmd_time = 0.0
        self._path: list[_Target] = []
        self._wp = 0
        self._aligning = False
        self._status = BaseStatus.IDLE
        self.collisions = 0
        self.distance = 0.0
        self.turned = 0.0

    # ------------------------------------------------------------------ queries
    @property
    def time(self) -> float:
        return self._time

    @property
    def status(self) -> BaseStatus:
        return self._status

    @property
    def true_pose(self) -> Pose2D:
        return Pose2D(*self._true, stamp=self.stamp_origin + self._time, frame_id="map")

    @property
    def odom_pose(self) -> Pose2D:
        return Pose2D(*self._odom, stamp=self.stamp_origin + self._time, frame_id="odom")

    @property
    def twist(self) -> Twist2D:
        return Twist2D(self._v, self._omega, self.stamp_origin + self._time)

    # ------------------------------------------------------------------ commands
    def command_velocity(self, twist: Twist2D) -> None:
        """Drive at ``twist`` (clipped to the limits) until the next command; cancels a goal."""
        if not (math.isfinite(twist.v) and math.isfinite(twist.omega)):
            raise ValueError(f"velocity command must be finite, got {twist}")
        self._cmd, self._cmd_time = twist, self._time
        self._path = []
        self._status = BaseStatus.VELOCITY

    def stop(self) -> None:
        """Brake to a stop (within the deceleration limits) and forget any goal."""
        self._cmd, self._path = None, []
        self._status = BaseStatus.IDLE

    def go_to(self, goal: Pose2D | tuple[float, float], *, align: bool = True) -> None:
        """Drive to ``goal``; with a Pose2D and ``align``, turn to its heading at the end."""
        self.follow_path([goal], align=align)

    def follow_path(self, waypoints: Sequence[Pose2D | tuple[float, float]], *, align: bool = True) -> None:
        """Drive through ``waypoints`` in order (world frame); the last one is the goal."""
        path: list[_Target] = []
        for w in waypoints:
            if isinstance(w, Pose2D):
                path.append((w.x, w.y, w.theta if align else None))
            else:
                path.append((float(w[0]), float(w[1]), None))
        if not path:
            raise ValueError("follow_path needs at least one waypoint")
        if not all(math.isfinite(p[0]) and math.isfinite(p[1]) for p in path):
            raise ValueError("waypoints must be finite (x, y) in metres")
        self._path, self._wp, self._aligning = path, 0, False
        self._cmd = None
        self._status = BaseStatus.GOAL

    # ------------------------------------------------------------------ simulation
    def step(self, dt: float) -> BaseState:
        """Advance the simulation by ``dt`` seconds."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt}")
        v_goal, w_goal, event = self._target_velocity()
        lim = self.limits
        v_goal = float(np.clip(v_goal, -lim.v_max, lim.v_max))
        w_goal = float(np.clip(w_goal, -lim.omega_max, lim.omega_max))
        self._v += float(np.clip(v_goal - self._v, -lim.accel * dt, lim.accel * dt))
        self._omega += float(np.clip(w_goal - self._omega, -lim.alpha * dt, lim.alpha * dt))
        collided = self._move(self._v * dt, self._omega * dt)
        if collided is not None:
            event = collided
        self._time += dt
        if self._status is BaseStatus.GOAL and not self._path:
            self._status = BaseStatus.REACHED
        return BaseState(self._time, self.true_pose, self.odom_pose, self.twist, self._status, event)

    def run_until_done(self, timeout: float, dt: float = 0.02) -> BaseState:
        """Step until the goal is reached, the base collides or ``timeout`` simulated seconds pass."""
        state = self.step(dt)
        end = self._time + timeout
        while state.status is BaseStatus.GOAL and self._time < end:
            state = self.step(dt)
        return state

    def _move(self, ds: float, dtheta: float) -> str | None:
        """Apply the motion in sub-steps short enough not to tunnel through a wall."""
        fine = 0.5 * self.world.grid.resolution if self.world is not None else math.inf
        n = max(1, math.ceil(abs(ds) / fine)) if math.isfinite(fine) else 1
        for _ in range(n):
            sds, sdth = ds / n, dtheta / n
            new = arc_step(self._true, sds, sdth)
            if self.world is not None and sds != 0.0:
                old_c = float(self.world.clearance(np.array(self._true[:2])))
                new_c = float(self.world.clearance(np.array(new[:2])))
                # moving away from a wall one is already touching is allowed (to back off)
                if new_c < self.radius and new_c < old_c:
                    return self._collide(new)
            self._true = new
            self._odometry(sds, sdth)
        return None

    def _collide(self, where: tuple[float, float, float]) -> str:
        self._v = self._omega = 0.0
        self._cmd, self._path = None, []
        self._status = BaseStatus.COLLIDED
        self.collisions += 1
        msg = (
            f"collision: stopped at ({self._true[0]:.2f}, {self._true[1]:.2f}) before touching "
            f"an obstacle near ({where[0]:.2f}, {where[1]:.2f})"
        )
        log.warning("sim base: %s", msg)
        return msg

    def _odometry(self, ds: float, dtheta: float) -> None:
        nz = self.noise
        ads, adt = abs(ds), abs(dtheta)
        self.distance += ads
        self.turned += adt
        ds_o = ds + self._rng.normal(0.0, nz.dist_std * math.sqrt(ads)) if nz.dist_std > 0 and ads > 0 else ds
        var_th = nz.turn_std**2 * adt + nz.drift_std**2 * ads
        dth_o = dtheta + self._rng.normal(0.0, math.sqrt(var_th)) if var_th > 0 else dtheta
        self._odom = arc_step(self._odom, ds_o, dth_o)

    # ------------------------------------------------------------------ control
    def _target_velocity(self) -> tuple[float, float, str | None]:
        if self._status is BaseStatus.VELOCITY and self._cmd is not None:
            if self.cmd_timeout is not None and self._time - self._cmd_time > self.cmd_timeout:
                self._cmd = None
                self._status = BaseStatus.IDLE
                return 0.0, 0.0, f"velocity command older than {self.cmd_timeout} s: stopping"
            return self._cmd.v, self._cmd.omega, None
        if self._status is BaseStatus.GOAL and self._path:
            return self._pursue()
        return 0.0, 0.0, None

    def _pursue(self) -> tuple[float, float, str | None]:
        c, lim = self.control, self.limits
        x, y, th = self._true
        event = None
        while True:
            tx, ty, tyaw = self._path[self._wp]
            final = self._wp == len(self._path) - 1
            dist = math.hypot(tx - x, ty - y)
            if final or dist > c.waypoint_tolerance:
                break
            self._wp += 1
            event = f"waypoint {self._wp}/{len(self._path)} passed"
        if final and (self._aligning or dist <= c.goal_tolerance):
            self._aligning = True
            err = 0.0 if tyaw is None else normalize_angle(tyaw - th)
            if abs(err) <= c.yaw_tolerance and abs(self._omega) < 0.05 and abs(self._v) < 0.02:
                self._path = []
                return 0.0, 0.0, f"goal ({tx:.2f}, {ty:.2f}) reached"
            # the aligning turn brakes in time: |ω| ≤ √(2·α·|err|)
            w = math.copysign(min(c.k_omega * abs(err), math.sqrt(2 * lim.alpha * abs(err))), err)
            return 0.0, w, event
        alpha = normalize_angle(math.atan2(ty - y, tx - x) - th)
        if abs(alpha) > c.turn_threshold:
            return 0.0, c.k_omega * alpha, event
        v = lim.v_max
        if final:
            v = min(v, c.k_v * dist, math.sqrt(2.0 * lim.accel * max(dist - 0.5 * c.goal_tolerance, 0.0)))
        kappa = 2.0 * math.sin(alpha) / max(dist, 1e-6)  # pure pursuit towards the waypoint
        if abs(v * kappa) > lim.omega_max:
            v = lim.omega_max / abs(kappa)
        return v, v * kappa, event


class SimBaseRunner(OdometrySource):
    """Steps a :class:`SimBase` from asyncio and publishes its odometry.

    ``realtime=True`` paces the steps to the wall clock (stamps are then epoch seconds);
    otherwise it runs as fast as it can, yielding to the event loop between steps. Commands
    go to :attr:`base` directly (same thread as the loop).
    """

    def __init__(
        self, base: SimBase, *, rate_hz: float = 50.0, realtime: bool = True, queue_size: int = 64
    ) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        super().__init__(frame_id="odom", queue_size=queue_size)
        self.base = base
        self.dt = 1.0 / rate_hz
        self.realtime = realtime
        self.state: BaseState | None = None
        self._done = asyncio.Event()

    async def run(self, duration: float | None = None) -> None:
        """Step until closed (or for ``duration`` simulated seconds)."""
        loop = asyncio.get_running_loop()
        if self.realtime:
            self.base.stamp_origin = time.time() - self.base.time
        t0, k = loop.time(), 0
        end = None if duration is None else self.base.time + duration
        while not self._closed and (end is None or self.base.time < end - 1e-9):
            self.state = self.base.step(self.dt)
            self._publish(self.state.odom)
            if self.state.event is not None:
                log.info("sim base: %s", self.state.event)
            if self.state.status is not BaseStatus.GOAL:
                self._done.set()
            else:
                self._done.clear()
            k += 1
            if self.realtime:
                await asyncio.sleep(max(0.0, t0 + k * self.dt - loop.time()))
            else:
                await asyncio.sleep(0)

    async def wait_done(self, timeout: float | None = None) -> BaseState:
        """Wait until the base is no longer pursuing a goal (reached or collided)."""

        async def wait() -> BaseState:
            await asyncio.sleep(0)
            while self.state is None or BaseStatus.GOAL in (self.state.status, self.base.status):
                self._done.clear()
                await self._done.wait()
            return self.state

        try:
            return await asyncio.wait_for(wait(), timeout)
        except TimeoutError as exc:
            raise DeviceTimeout(f"the simulated base did not finish its goal within {timeout} s") from exc
