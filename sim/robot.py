"""The simulated robot: a base driving in a world, with the laser (and camera) it carries.

One world — a generated office (``gen:SEED``, ``tour:SEED``) or a map file — and in it:

* a :class:`~drivers.sim.base.SimBase` (differential drive; true pose vs noisy odometry;
  stops at walls) stepped by a background thread every ``1/odom_rate`` simulated seconds,
  paced to the wall clock times ``speed``;
* a laser whose pose follows the base's **true** pose through its mount: by default a 180°
  SICK LMS 2xx on a pseudo-terminal (:class:`~drivers.sim.lms.VirtualLMS`: the real
  driver talks to it, at the scanner's own rate), or a 360° scanner whose scans are handed
  to listeners as :class:`~drivers.messages.LaserScan` (no LMS 2xx sweeps 360°, so there is
  no serial line to emulate);
* optional walking people (their legs show in the scans) and an optional
  :class:`~sim.camera_view.VirtualCamera` rendering JPEG frames from the true pose, with
  the building's furniture as pictures;
* what the base does: follow a scripted route (given waypoints, or a tour of the building's
  rooms through their doors, :mod:`sim.route`), a velocity command, or a goal (a
  pose or a path, in the odometry or the map frame; planned around walls unless told not;
  a planned goal given while the base stands against an obstacle, or right after its last
  goal ended in a collision, backs off straight away from the obstacle first, as a real
  base's local planner would, instead of stopping at once).

Every step the listeners get a :class:`RobotSample` (odometry in frame ``"odom"``, the true
pose in frame ``"map"``, the place class at the true pose); goal and motion events are
:class:`StatusReport` s. Listeners run on the robot's thread and must return quickly.

Time: simulated seconds advance ``speed`` times as fast as the wall clock, and every step is
stamped with the wall-clock time its simulated time stands for (the start time plus the
simulated seconds divided by ``speed``), as a real base's encoders measure the motion when it
happens, whoever reads them when. The simulation is a function of that clock:
:meth:`SimRobot.advance_to` steps it up to a time (under a lock), and the robot's thread
calls it every period; the virtual LMS asks for the world at each scan's measurement time
(:meth:`SimRobot.sensor_pose_at`, the legs likewise), which advances the simulation first
if its thread is behind, and interpolates the steps around that time. So a thread the
machine starves for a moment delays when odometry and scans are *delivered*, never what
they say or their stamps: the catch-up steps carry the stamps of the times they simulate,
and the scan measured at time t sees the robot where it was at t. A robot more than
:data:`MAX_CATCH_UP` seconds behind skips ahead (the world stands still over the gap,
logged) instead of replaying the lost time. Stepped by hand (:meth:`SimRobot.step` without a
stamp), stamps are the start time plus simulated seconds divided by ``speed``: deterministic.

The thread-safe commands (:meth:`SimRobot.command_velocity`, :meth:`SimRobot.send_goal`,
:meth:`SimRobot.cancel`) are queued and applied at the next step. Without :meth:`start`,
:meth:`SimRobot.step` advances the simulation by hand (deterministic, for tests).
"""

from __future__ import annotations

import bisect
import collections
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from drivers.messages import CameraFrame, LaserScan, Pose2D, Twist2D
from drivers.sim.base import BaseStatus, ControllerParams, OdometryNoise, SimBase
from drivers.sim.lms import VirtualLMS
from knowledge.errors import ConfigError, MapError
from knowledge.labels import CLASS_NAMES
from knowledge.metric.beams import beam_angles
from knowledge.metric.raycast import cast
from sim.buildings import Building
from sim.camera_view import VirtualCamera
from sim.lms_world import Leg, LmsWorld, default_sensor_pose, ray_circle_ranges
from sim.objects import WorldObject
from sim.people import SimPerson, walkers_in
from sim.route import Route, RoutePlanner, building_tour, corridor_start, resample, split_at_turns
from sim.world import SimWorld, load_tour, load_world

if TYPE_CHECKING:
    pass

log = logging.getLogger(__name__)

Point = tuple[float, float]
#: One step in the lasers' history: stamp, the sensor's world x, y, heading, (L, 2) leg centres.
_Step = tuple[float, float, float, float, np.ndarray]

#: What the base is doing, as :class:`StatusReport` says it.
STATUSES = ("idle", "velocity", "route", "active", "reached", "collided", "failed", "cancelled")
#: Collisions on a scripted route after which the robot gives up on it.
MAX_ROUTE_COLLISIONS = 20
#: A goal fails when not reached within this many seconds plus 3x its length at full speed.
GOAL_SLACK_S = 30.0
#: Metres a planned goal's waypoint may be moved to keep clear of obstacles.
SNAP_DISTANCE = 0.5
#: Metres of clearance beyond the base's radius within which it counts as touching an obstacle.
TOUCHING = 0.03
#: Seconds the simulation may fall behind the wall clock before it skips ahead.
MAX_CATCH_UP = 1.0
#: Seconds of steps kept for the lasers' look-ups at a scan's measurement time.
HISTORY = 3.0
#: Furniture kinds shown to the camera, as catalogue kinds of :mod:`sim.objects`.
_PICTURE_KIND = {
    "couch": "couch",
    "tv": "television",
    "shelf": "bookcase",
    "fridge": "fridge",
    "desk": "desk",
    "table": "table",
    "plant": "plant",
    "charging_station": "charging_station",
    "bucket": "bucket",
}


@dataclass(frozen=True)
class Mount:
    """Where a sensor sits on the robot: ``x`` forward and ``y`` left (metres), ``yaw`` (radians)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x, self.y, self.yaw)):
            raise ValueError(f"a mount needs finite x, y (m) and yaw (rad), got {(self.x, self.y, self.yaw)}")

    def apply(self, pose: tuple[float, float, float]) -> tuple[float, float, float]:
        """The sensor's world pose for the robot's world pose ``(x, y, theta)``."""
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        return (x + c * self.x - s * self.y, y + s * self.x + c * self.y, th + self.yaw)


@dataclass(frozen=True)
class SimRobotConfig:
    """Everything a :class:`SimRobot` is made of (see the module docstring).

    Attributes:
        world: ``gen:SEED`` (a generated office), ``tour:SEED`` (a generated tour office),
            ``demo:SEED`` (the guided tour's office of :mod:`sim.tour`, with its
            objects for the camera, starting at the charging station), a map_server
            ``.yaml`` or an image (with ``resolution`` metres per cell).
        start: the true start pose ``(x, y, heading)`` in metres and radians; None: the first
            route point, else the middle of a corridor (buildings) or the free cell nearest
            the map centre.
        laser: ``"front"`` (a 180° LMS 2xx on a pty) or ``"360"`` (scans to the listeners).
        mount: the laser's place on the robot.
        link: the LMS device path to publish (a symlink); None: a temporary directory.
        lms_rate: LMS scans per second (None: the scanner's own, 37.5 Hz at 0.5°).
        lms_variant: LMS power-up ``(angle degrees, resolution degrees)``.
        lms_units: ``"cm"`` or ``"mm"``.
        lms_index: the LMS is configured to send real-time scan indices (a scanner set up
            with SICK's configuration tool or ``lms_config``), which the driver stamps from.
        beams, scan_range, scan_rate: the 360° laser's beams per turn, range (m) and scans
            per simulated second.
        noise: laser range noise, metres (standard deviation, hits only).
        people: how many people walk around near the start.
        camera: render camera frames; camera_rate frames per wall-clock second;
            camera_size ``(width, height)`` pixels.
        odom_rate: simulation steps (and odometry samples) per simulated second.
        speed: simulated seconds per wall-clock second.
        route: waypoints ``(x, y)`` (map frame) to drive through from the start.
        tour: drive a tour of the building's rooms and halls through their doors.
        tour_rooms: visit at most this many rooms (the nearest first).
        loop: drive the route again and again (an open route is closed by a straight
            segment back to its first point).
        odom_noise: odometry errors of the base.
        odom_start: the odometry's pose at the start (None: the true start pose, so that
            odometry minus truth is the drift; ``(0, 0, 0)``: like a real base switched on).
        cmd_timeout: a velocity command older than this (simulated seconds) stops the base.
        seed: seeds the odometry noise, the laser noise and the people.
    """

    world: str = "gen:0"
    resolution: float | None = None
    start: tuple[float, float, float] | None = None
    laser: str = "front"
    mount: Mount = field(default_factory=Mount)
    link: str | Path | None = None
    lms_rate: float | None = None
    lms_variant: tuple[int, float] = (180, 0.5)
    lms_units: str = "cm"
    lms_index: bool = True
    beams: int = 360
    scan_range: float = 30.0
    scan_rate: float = 10.0
    noise: float = 0.01
    people: int = 0
    camera: bool = False
    camera_rate: float = 2.0
    camera_size: tuple[int, int] = (320, 240)
    odom_rate: float = 50.0
    speed: float = 1.0
    route: tuple[Point, ...] = ()
    tour: bool = False
    tour_rooms: int | None = None
    loop: bool = False
    odom_noise: OdometryNoise = field(default_factory=OdometryNoise)
    odom_start: tuple[float, float, float] | None = None
    cmd_timeout: float | None = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.laser not in ("front", "360"):
            raise ConfigError(f"laser must be 'front' (a 180° LMS on a pty) or '360', got {self.laser!r}")
        for name in ("odom_rate", "scan_rate", "camera_rate", "scan_range"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name} must be a positive number, got {v!r}")
        if not (math.isfinite(self.speed) and 0 < self.speed <= 100):
            raise ConfigError(f"speed must be in (0, 100] simulated seconds per second, got {self.speed!r}")
        if self.beams < 8:
            raise ConfigError(f"the 360° laser needs at least 8 beams, got {self.beams}")
        if self.people < 0:
            raise ConfigError(f"people must be >= 0, got {self.people}")
        if self.tour and self.route:
            raise ConfigError("give a route or a tour, not both")
        if self.tour_rooms is not None and self.tour_rooms < 1:
            raise ConfigError(f"tour_rooms must be >= 1, got {self.tour_rooms}")
        if not (math.isfinite(self.noise) and self.noise >= 0):
            raise ConfigError(f"noise must be >= 0 metres, got {self.noise!r}")


@dataclass(frozen=True)
class Goal:
    """Where the base should go.

    Attributes:
        id: names the goal in status reports; a goal whose id was seen before is ignored.
        points: ``(x, y)`` waypoints, the last one the goal (at least one).
        heading: the heading to turn to at the goal (radians), or None.
        frame_id: ``"odom"`` (the agent's frame: converted with the odometry's current
            offset from the true pose) or ``"map"`` (the world's frame).
        plan: plan a collision-free route through the points (False: straight lines).
    """

    id: str
    points: tuple[Point, ...]
    heading: float | None = None
    frame_id: str = "odom"
    plan: bool = True

    def __post_init__(self) -> None:
        if not self.points:
            raise ValueError("a goal needs at least one (x, y) point")
        vals = [v for p in self.points for v in p] + ([self.heading] if self.heading is not None else [])
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("goal points and heading must be finite")
        if self.frame_id not in ("odom", "map"):
            raise ValueError(f"a goal's frame_id must be 'odom' or 'map', got {self.frame_id!r}")


@dataclass(frozen=True)
class StatusReport:
    """A change in what the base does.

    Attributes:
        stamp: seconds since the epoch (see the module docstring).
        status: one of :data:`STATUSES`.
        goal: the goal's id (``"route"`` for the scripted route), or None.
        reason: what happened, for people.
        odom: the odometry pose then.
        distance: metres driven so far.
    """

    stamp: float
    status: str
    goal: str | None
    reason: str | None
    odom: Pose2D
    distance: float


@dataclass(frozen=True)
class RobotSample:
    """One simulation step.

    Attributes:
        stamp: seconds since the epoch.
        time: simulated seconds since the start.
        odom: the odometry pose (frame ``"odom"``).
        truth: the true pose (frame ``"map"``).
        twist: the velocity driven.
        space: the id of the building's space at the true position (0: unknown or none).
        label: the place class at the true position (``room``, ``corridor``, ``doorway``,
            ``hallway``), None without ground truth.
        collisions: collisions so far.
    """

    stamp: float
    time: float
    odom: Pose2D
    truth: Pose2D
    twist: Twist2D
    space: int
    label: str | None
    collisions: int


def furniture_pictures(building: Building) -> tuple[WorldObject, ...]:
    """Pictures of the building's furniture for the camera: one on each item's front face."""
    grid = building.grid
    out: list[WorldObject] = []
    for i, f in enumerate(building.furniture):
        kind = _PICTURE_KIND.get(f.kind)
        if kind is None:
            continue
        face = f.yaw + math.pi / 2
        depth = f.size[1] / 2 + 0.05
        x, y = f.center[0] + depth * math.cos(face), f.center[1] + depth * math.sin(face)
        rc = grid.world_to_cell(np.array([x, y]))
        if not bool(grid.in_bounds(rc)) or not bool(grid.free[rc[0], rc[1]]):
            continue
        out.append(
            WorldObject.place(kind, x, y, face, name=f"{kind}{i}", width_m=max(0.3, min(f.size[0], 2.5)))
        )
    return tuple(out)


class SimRobot:
    """The simulated robot (see the module docstring)."""

    def __init__(self, config: SimRobotConfig | None = None) -> None:
        self.config = cfg = config or SimRobotConfig()
        #: the guided tour's world (``demo:SEED``), else None
        self.tour = load_tour(cfg.world)
        self.grid, self.building = load_world(cfg.world, cfg.resolution)
        if self.building is not None:
            self.planner = RoutePlanner.for_building(self.building)
        else:
            self.planner = RoutePlanner(self.grid)
        self.route = self._make_route()
        start = self._start_pose()
        self.dt = 1.0 / cfg.odom_rate
        objects: tuple[WorldObject, ...] = ()
        if self.tour is not None:
            objects = self.tour.objects
        elif cfg.camera and self.building is not None:
            objects = furniture_pictures(self.building)
        self.world = SimWorld(self.grid, objects)
        self.base = SimBase(
            self.world,
            Pose2D(*start, frame_id="map"),
            noise=cfg.odom_noise,
            control=ControllerParams(waypoint_tolerance=0.1),
            seed=cfg.seed,
            odom_start=None if cfg.odom_start is None else Pose2D(*cfg.odom_start),
            cmd_timeout=cfg.cmd_timeout,
        )
        self.people: list[SimPerson] = walkers_in(
            self.grid, (start[0], start[1]), cfg.people, seed=cfg.seed, reach=6.0
        )
        self.legs = [Leg(self._leg_position(p, k), p.gait.leg_radius) for p in self.people for k in (0, 1)]
        self._sensor = cfg.mount.apply(start)
        self._truth = self.base.true_pose
        self._lock = threading.RLock()  # the simulation's state: stepped by the robot's thread or a laser's
        # (stamp, sensor x, y, heading, (L, 2) leg centres) of the last HISTORY seconds of steps
        self._history: collections.deque[_Step] = collections.deque(
            maxlen=max(8, int(HISTORY * cfg.odom_rate / cfg.speed) + 2)
        )
        self.lms: VirtualLMS | None = None
        self._lms_world: LmsWorld | None = None
        if cfg.laser == "front":
            lms_world = self._lms_world = LmsWorld(
                self.grid, self._lms_sensor_pose, self._lms_legs(), noise_std=cfg.noise, seed=cfg.seed
            )
            angle, res = cfg.lms_variant
            self.lms = VirtualLMS(
                lms_world,
                link=cfg.link,
                rate=cfg.lms_rate,
                angle=angle,
                resolution=res,
                units=cfg.lms_units,
                realtime_index=cfg.lms_index,
                seed=cfg.seed,
            )
        self.camera = (
            VirtualCamera(self.world, width=cfg.camera_size[0], height=cfg.camera_size[1])
            if cfg.camera
            else None
        )
        self._scan_rng = np.random.default_rng(cfg.seed + 1)
        self._scan_every = max(1, round(cfg.odom_rate / cfg.scan_rate))
        self._scan_seq = 0
        self._frame_seq = 0
        self._steps = 0
        self._origin = time.time()
        self._stamp = self._origin
        self._commands: queue.Queue[tuple[str, Any]] = queue.Queue()
        self._seen_goals: collections.deque[str] = collections.deque(maxlen=256)
        self._activity = "idle"
        self._goal_id: str | None = None
        self._deadline = math.inf
        self._route_collisions = 0
        self._legs: list[np.ndarray] = []
        self._heading: float | None = None
        self._last_status: tuple[str, str | None] | None = None
        self.sample_listeners: list[Callable[[RobotSample], None]] = []
        self.status_listeners: list[Callable[[StatusReport], None]] = []
        self.scan_listeners: list[Callable[[LaserScan], None]] = []
        self.frame_listeners: list[Callable[[CameraFrame], None]] = []
        self._stop = threading.Event()
        self._running = False
        self._threads: list[threading.Thread] = []
        self.latest: RobotSample | None = None
        if self.route is not None:
            self._follow_route(0)

    # ------------------------------------------------------------------ set-up
    def _make_route(self) -> Route | None:
        cfg = self.config
        if cfg.tour:
            if self.building is None:
                raise ConfigError("a tour needs a generated building as the world (gen:SEED or tour:SEED)")
            start = None if cfg.start is None else cfg.start[:2]
            return building_tour(
                self.building, start, max_rooms=cfg.tour_rooms, closed=True, planner=self.planner
            )
        if cfg.route:
            pts = [tuple(p) for p in cfg.route]
            if cfg.start is not None:
                pts.insert(0, (cfg.start[0], cfg.start[1]))
            if cfg.loop and len(pts) > 2 and pts[-1] != pts[0]:
                pts.append(pts[0])
            return Route(np.asarray(pts, dtype=np.float64), spacing=self.planner.params.spacing)
        return None

    def _start_pose(self) -> tuple[float, float, float]:
        cfg = self.config
        if cfg.start is not None:
            return cfg.start
        if self.tour is not None and self.route is None:
            return self.tour.start
        if self.route is not None:
            x, y = self.route.start
            return (x, y, self.route.start_heading)
        if self.building is not None:
            return corridor_start(self.building, self.planner)
        return default_sensor_pose(self.grid)

    def _leg_position(self, person: SimPerson, k: int) -> Callable[[float], Point]:
        def pos(_t: float) -> Point:
            p = person.leg_positions(self.base.time)[k]
            return (float(p[0]), float(p[1]))

        return pos

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> Path | None:
        """Start the LMS (if any) and the robot's threads; returns the LMS device path."""
        if self._threads:
            raise RuntimeError("the simulated robot is already running")
        with self._lock:
            self._origin = time.time() - self.base.time / self.config.speed
            self._stamp = self._origin + self.base.time / self.config.speed
            self._history.clear()
            self._record(self._stamp)
        path = self.lms.start() if self.lms is not None else None
        self._stop.clear()
        self._running = True
        self._threads = [threading.Thread(target=self._run, name="sim-robot", daemon=True)]
        if self.camera is not None:
            self._threads.append(threading.Thread(target=self._run_camera, name="sim-camera", daemon=True))
        for t in self._threads:
            t.start()
        return path

    def stop(self) -> None:
        """Stop the threads and the LMS (its device path disappears)."""
        self._running = False
        self._stop.set()
        for t in self._threads:
            t.join(5.0)
        self._threads = []
        if self.lms is not None:
            self.lms.stop()

    def __enter__(self) -> SimRobot:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def device(self) -> Path | None:
        """The LMS device path while running (None for the 360° laser)."""
        return self.lms.link if self.lms is not None and self._threads else None

    @property
    def sensor_pose(self) -> tuple[float, float, float]:
        """The laser's true world pose ``(x, y, heading)`` after the last step (metres, radians)."""
        return self._sensor

    @property
    def origin(self) -> float:
        """The epoch seconds simulated time 0 stands for (see the module docstring)."""
        return self._origin

    def stamp(self) -> float:
        """The stamp of the last step, epoch seconds (see the module docstring)."""
        return self._stamp

    # ------------------------------------------------------------------ commands (any thread)
    def command_velocity(self, v: float, omega: float) -> None:
        """Drive at ``v`` m/s and ``omega`` rad/s (clipped to the base's limits); cancels goals."""
        if not (math.isfinite(v) and math.isfinite(omega)):
            raise ValueError(f"a velocity command must be finite, got v={v}, omega={omega}")
        self._commands.put(("twist", (float(v), float(omega))))

    def send_goal(self, goal: Goal) -> None:
        """Drive to ``goal`` (replacing the route, a velocity command or another goal)."""
        self._commands.put(("goal", goal))

    def cancel(self) -> None:
        """Stop whatever the base is doing."""
        self._commands.put(("cancel", None))

    def add_person(self, legs: Sequence[Leg], on_step: Callable[[RobotSample], None] | None = None) -> None:
        """Put a person's ``legs`` into the lasers' world (360° scans and the LMS) and call
        ``on_step`` with every step's sample (on the robot's thread; it must be quick).

        Call before :meth:`start` or from the robot's thread: the lists are not locked.
        """
        self.legs.extend(legs)
        if self._lms_world is not None:
            # the LMS's world keeps its own tuple of legs: each looked up at the scan's time
            self._lms_world.legs = tuple(self._lms_legs())
        if on_step is not None:
            self.sample_listeners.append(on_step)

    # ------------------------------------------------------------------ simulation
    def step(self, stamp: float | None = None) -> RobotSample:
        """Advance the simulation by one step (``1/odom_rate`` simulated seconds).

        ``stamp``: epoch seconds of the step (default: the start time plus the simulated
        seconds divided by ``speed``, the simulated clock); stamps always increase.
        """
        with self._lock:
            return self._step(stamp)

    def advance_to(self, stamp: float) -> int:
        """Step the simulation until its clock reaches ``stamp`` (epoch seconds); returns the
        steps taken. More than :data:`MAX_CATCH_UP` seconds behind, the clock skips ahead
        first (the world stands still over the gap)."""
        speed = self.config.speed
        n = 0
        with self._lock:
            behind = stamp - (self._origin + self.base.time / speed)
            if behind > MAX_CATCH_UP:
                log.warning("simulated robot: %.1f s behind the wall clock; skipping ahead", behind)
                self._origin += behind - self.dt / speed
            while self._origin + (self.base.time + self.dt) / speed <= stamp:
                self._step(None)
                n += 1
        return n

    def sensor_pose_at(self, stamp: float) -> tuple[float, float, float]:
        """The laser's true world pose at ``stamp`` (epoch seconds), interpolated between the
        steps around it (the oldest or newest kept step's beyond them)."""
        with self._lock:
            a, b, f = self._around(stamp)
            dth = math.atan2(math.sin(b[3] - a[3]), math.cos(b[3] - a[3]))
            return (a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]), a[3] + f * dth)

    def legs_at(self, stamp: float) -> np.ndarray:
        """``(L, 2)`` the centres of every leg in the world at ``stamp`` (epoch seconds)."""
        with self._lock:
            a, b, f = self._around(stamp)
            if a[4].shape != b[4].shape:
                return b[4] if f >= 0.5 else a[4]
            return np.asarray(a[4] + f * (b[4] - a[4]))

    def _around(self, stamp: float) -> tuple[_Step, _Step, float]:
        h = self._history
        if not h:
            self._record(self._stamp)
        if stamp <= h[0][0]:
            return h[0], h[0], 0.0
        if stamp >= h[-1][0]:
            return h[-1], h[-1], 0.0
        i = bisect.bisect_right([e[0] for e in h], stamp)
        a, b = h[i - 1], h[i]
        return a, b, (stamp - a[0]) / (b[0] - a[0])

    def _record(self, stamp: float) -> None:
        t = self.base.time
        legs = np.array([leg.at(t) for leg in self.legs], dtype=np.float64).reshape(-1, 2)
        x, y, th = self._sensor
        self._history.append((stamp, float(x), float(y), float(th), legs))

    def _lms_sensor_pose(self, t: float) -> tuple[float, float, float]:
        """The LMS's view: ``t`` is seconds since the virtual scanner started."""
        if self.lms is None or not self._running:
            return self._sensor
        stamp = self.lms.epoch(t)
        self.advance_to(stamp)
        return self.sensor_pose_at(stamp)

    def _lms_legs(self) -> list[Leg]:
        def at(k: int) -> Callable[[float], Point]:
            def pos(t: float) -> Point:
                if self.lms is None or not self._running:
                    p = self.legs[k].at(self.base.time)
                else:
                    legs = self.legs_at(self.lms.epoch(t))
                    p = legs[k] if k < legs.shape[0] else self.legs[k].at(self.base.time)
                return (float(p[0]), float(p[1]))

            return pos

        return [Leg(at(k), leg.radius) for k, leg in enumerate(self.legs)]

    def _step(self, stamp: float | None) -> RobotSample:
        while True:
            try:
                kind, arg = self._commands.get_nowait()
            except queue.Empty:
                break
            self._apply(kind, arg)
        state = self.base.step(self.dt)
        self._steps += 1
        t = self._origin + state.time / self.config.speed if stamp is None else stamp
        self._stamp = stamp = max(t, self._stamp + 1e-6)
        self._after_step(state.status, state.event)
        truth = state.true_pose
        self._truth = truth
        self._sensor = self.config.mount.apply((truth.x, truth.y, truth.theta))
        space, label = self._ground_truth(truth)
        o = state.odom
        sample = RobotSample(
            stamp=stamp,
            time=state.time,
            odom=Pose2D(o.x, o.y, o.theta, stamp=stamp, frame_id="odom"),
            truth=Pose2D(truth.x, truth.y, truth.theta, stamp=stamp, frame_id="map"),
            twist=Twist2D(state.twist.v, state.twist.omega, stamp),
            space=space,
            label=label,
            collisions=self.base.collisions,
        )
        self.latest = sample
        self._notify(self.sample_listeners, sample)
        self._record(stamp)  # after the listeners: the tutor's legs have moved with this step
        if self.config.laser == "360" and self._steps % self._scan_every == 0:
            self._notify(self.scan_listeners, self.scan_360(stamp))
        return sample

    def run_for(self, seconds: float) -> RobotSample | None:
        """Step by hand for ``seconds`` of simulated time; returns the last sample."""
        last = None
        for _ in range(max(0, round(seconds / self.dt))):
            last = self.step()
        return last

    def scan_360(self, stamp: float | None = None) -> LaserScan:
        """A 360° scan from the sensor's true pose: beam ``i`` at ``i·2π/beams``."""
        cfg = self.config
        pose = np.asarray(self._sensor, dtype=np.float64)
        n, rmax = cfg.beams, cfg.scan_range
        r = cast(self.grid, pose, n_beams=n, max_range=rmax).astype(np.float64)
        if self.legs:
            t = self.base.time
            centres = np.array([leg.at(t) for leg in self.legs])
            radii = np.array([leg.radius for leg in self.legs])
            r = np.minimum(r, ray_circle_ranges((pose[0], pose[1]), pose[2] + beam_angles(n), centres, radii))
        hit = r < rmax
        if cfg.noise > 0:
            r = np.where(hit, r + self._scan_rng.normal(0.0, cfg.noise, r.shape), r)
        self._scan_seq += 1
        return LaserScan(
            stamp=self.stamp() if stamp is None else stamp,
            seq=self._scan_seq,
            frame_id="laser",
            angle_min=0.0,
            angle_increment=2 * math.pi / n,
            range_max=rmax,
            ranges=np.clip(r, 0.0, rmax),
            scan_time=1.0 / cfg.scan_rate,
        )

    def render_frame(self) -> CameraFrame:
        """A JPEG camera frame from the robot's true pose."""
        if self.camera is None:
            raise RuntimeError("this simulated robot has no camera (SimRobotConfig.camera)")
        truth = self._truth
        image = self.camera.render(truth)
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 85])
        if not ok:
            raise RuntimeError("OpenCV could not encode the camera image as JPEG")
        self._frame_seq += 1
        return CameraFrame(stamp=self.stamp(), seq=self._frame_seq, frame_id="camera", jpeg=buf.tobytes())

    # ------------------------------------------------------------------ internals
    def _run(self) -> None:
        period = self.dt / self.config.speed
        while not self._stop.is_set():
            try:
                self.advance_to(time.time())
            except Exception:  # a broken step must not leave a silent robot behind
                log.exception("simulated robot: a step failed")
            with self._lock:
                due = self._origin + (self.base.time + self.dt) / self.config.speed
            self._stop.wait(min(period, max(0.0, due - time.time())))

    def _run_camera(self) -> None:
        period = 1.0 / self.config.camera_rate
        while not self._stop.wait(period):
            try:
                self._notify(self.frame_listeners, self.render_frame())
            except Exception:
                log.exception("simulated camera: rendering a frame failed")

    def _notify(self, listeners: list[Callable[[Any], None]], item: Any) -> None:
        for fn in listeners:
            try:
                fn(item)
            except Exception:
                log.exception("simulated robot: a listener failed")

    def _ground_truth(self, truth: Pose2D) -> tuple[int, str | None]:
        self._truth = truth
        b = self.building
        if b is None:
            return 0, None
        rc = b.grid.world_to_cell(np.array([truth.x, truth.y]))
        if not bool(b.grid.in_bounds(rc)):
            return 0, None
        return int(b.spaces[rc[0], rc[1]]), CLASS_NAMES.get(int(b.labels[rc[0], rc[1]]))

    def _report(self, status: str, reason: str | None = None, *, force: bool = False) -> None:
        key = (status, self._goal_id)
        if not force and key == self._last_status:
            return
        self._last_status = key
        o = self.base.odom_pose
        stamp = self.stamp()
        report = StatusReport(
            stamp=stamp,
            status=status,
            goal=self._goal_id,
            reason=reason,
            odom=Pose2D(o.x, o.y, o.theta, stamp=stamp, frame_id="odom"),
            distance=self.base.distance,
        )
        log.info("simulated robot: %s%s", status, f" ({reason})" if reason else "")
        self._notify(self.status_listeners, report)

    def _apply(self, kind: str, arg: Any) -> None:
        if kind == "twist":
            v, w = arg
            if self._activity in ("goal", "route"):
                self._report("cancelled", "a velocity command took over")
            self.base.command_velocity(Twist2D(v, w))
            self._activity, self._goal_id = "velocity", None
            self._report("velocity")
        elif kind == "cancel":
            self.base.stop()
            if self._activity != "idle":
                self._report("cancelled", "cancelled")
            self._activity, self._goal_id = "idle", None
            self._report("idle")
        elif kind == "goal":
            goal: Goal = arg
            if goal.id in self._seen_goals:
                return
            self._seen_goals.append(goal.id)
            if self._activity in ("goal", "route"):
                self._report("cancelled", f"goal {goal.id} took over")
            self._start_goal(goal)

    def _start_goal(self, goal: Goal) -> None:
        self._activity, self._goal_id = "goal", goal.id
        pts = np.asarray(goal.points, dtype=np.float64)
        heading = goal.heading
        truth, odom = self.base.true_pose, self.base.odom_pose
        if goal.frame_id == "odom":
            # the odometry frame's pose in the map: true ⊕ odom⁻¹, as the base sees it now
            dth = truth.theta - odom.theta
            c, s = math.cos(dth), math.sin(dth)
            d = pts - np.array([odom.x, odom.y])
            pts = np.column_stack((truth.x + c * d[:, 0] - s * d[:, 1], truth.y + s * d[:, 0] + c * d[:, 1]))
            heading = None if heading is None else heading + dth
        here = np.array([[truth.x, truth.y]])
        start = here
        stopped = self.base.status is BaseStatus.COLLIDED  # by the last goal, and not moved since
        if goal.plan and (stopped or float(self.world.clearance(here[0])) < self.base.radius + TOUCHING):
            # stopped against an obstacle (a follower cutting a corner behind its person): back
            # off straight away from its nearest cell first, then plan from there; else every
            # new goal would stop at once (a route's first leg may run along the obstacle,
            # whose cells' clearances the base compares)
            away = self._away_from_obstacle(here[0])
            if away is not None:
                start = np.vstack([here, away])
        if goal.plan:
            # waypoints hugging an obstacle (a follower aiming beside a narrow gap, a doorway
            # node seen through drifted odometry): the nearest points the planner keeps clear
            # of obstacles, or the base would stop there for fear of a collision
            pts = pts.copy()
            # (only nearby: a goal in a wall or off the map still fails)
            for i, p in enumerate(pts):
                if float(self.planner.clearance(p)) < self.planner.params.clearance:
                    q = self.planner.nearest_clear(p)
                    if math.dist(q, p) <= SNAP_DISTANCE:
                        pts[i] = q
        try:
            if goal.plan:
                path = self.planner.plan_through(np.vstack([start[-1:], pts])).dense()
                if len(start) > 1:
                    path = np.vstack([start[:1], path])
            else:
                path = resample(np.vstack([here, pts]), self.planner.params.spacing)
        except (MapError, ValueError) as exc:
            self.base.stop()
            self._finish("failed", str(exc))
            return
        length = float(np.hypot(*np.diff(path, axis=0).T).sum())
        self._deadline = self.base.time + GOAL_SLACK_S + 3.0 * length / self.base.limits.v_max
        self._drive(path, heading)
        self._report("active", f"{length:.1f} m")

    def _away_from_obstacle(self, xy: np.ndarray, distance: float = 0.15) -> np.ndarray | None:
        """The point ``distance`` metres from ``xy`` straight away from the nearest occupied
        cell within a metre (None: none there)."""
        g = self.grid
        rc = g.world_to_cell(np.asarray(xy, dtype=np.float64))
        k = math.ceil(1.0 / g.resolution)
        r0, c0 = max(int(rc[0]) - k, 0), max(int(rc[1]) - k, 0)
        occ = g.occupied[r0 : int(rc[0]) + k + 1, c0 : int(rc[1]) + k + 1]
        cells = np.argwhere(occ)
        if cells.size == 0:
            return None
        centres = g.cell_to_world(cells + np.array([r0, c0]))
        d = np.asarray(xy, dtype=np.float64) - centres
        j = int(np.argmin(np.hypot(d[:, 0], d[:, 1])))
        n = float(np.hypot(*d[j]))
        if n < 1e-9:
            return None
        return np.asarray(xy, dtype=np.float64) + distance * d[j] / n

    def _drive(self, path: np.ndarray, heading: float | None) -> None:
        """Follow ``path`` ``(m, 2)`` (its first point: about here), stopping at sharp corners."""
        self._legs = split_at_turns(path)
        self._heading = heading
        self._next_leg()

    def _next_leg(self) -> bool:
        """Start the next piece of the path; False when there is none left."""
        if not self._legs:
            return False
        leg = self._legs.pop(0)
        pts = leg[1:] if len(leg) > 1 else leg
        waypoints: list[Pose2D | tuple[float, float]] = [(float(x), float(y)) for x, y in pts]
        align = not self._legs and self._heading is not None
        if align and self._heading is not None:
            waypoints[-1] = Pose2D(float(pts[-1, 0]), float(pts[-1, 1]), self._heading)
        self.base.follow_path(waypoints, align=align)
        return True

    def _follow_route(self, start_index: int) -> None:
        assert self.route is not None
        dense = self.route.dense()
        self._drive(dense[min(start_index, len(dense) - 1) :], None)
        self._activity, self._goal_id = "route", "route"
        self._deadline = math.inf

    def _finish(self, status: str, reason: str | None) -> None:
        """Report how a goal or the route ended; the base is idle afterwards."""
        self._report(status, reason, force=True)
        self._activity, self._goal_id = "idle", None
        self._last_status = ("idle", None)  # no separate "idle" report after an ending

    def _after_step(self, status: BaseStatus, event: str | None) -> None:
        act = self._activity
        if act == "idle":
            self._report("idle")
        elif act == "route":
            self._report("route")
            if status is BaseStatus.REACHED and self._next_leg():
                pass
            elif status is BaseStatus.REACHED:
                if self.config.loop and self.route is not None and len(self.route.waypoints) > 1:
                    self._report("reached", "route driven; once more", force=True)
                    self._follow_route(0)
                else:
                    self._finish("reached", "route driven")
            elif status is BaseStatus.COLLIDED:
                self._route_collisions += 1
                self._report("collided", event, force=True)
                if self._route_collisions > MAX_ROUTE_COLLISIONS:
                    self._finish("failed", f"{MAX_ROUTE_COLLISIONS} collisions on the route; stopped")
                else:  # carry on with the waypoints ahead
                    assert self.route is not None
                    dense = self.route.dense()
                    here = np.array([self.base.true_pose.x, self.base.true_pose.y])
                    self._follow_route(int(np.argmin(np.hypot(*(dense - here).T))))
        elif act == "goal":
            if status is BaseStatus.REACHED and self._next_leg():
                pass
            elif status is BaseStatus.REACHED:
                self._finish("reached", event)
            elif status is BaseStatus.COLLIDED:
                self._finish("collided", event)
            elif self.base.time > self._deadline:
                self.base.stop()
                self._finish("failed", "not reached in time")
        elif act == "velocity":
            if status is BaseStatus.COLLIDED:
                self._finish("collided", event)
            elif status is not BaseStatus.VELOCITY:
                self._activity = "idle"
                self._report("idle", event)

    def state(self) -> dict[str, Any]:
        """A summary for people: what it does, where it is, how far it drove."""
        t = self.base.true_pose
        return {
            "activity": self._activity,
            "goal": self._goal_id,
            "time": round(self.base.time, 3),
            "truth": (round(t.x, 3), round(t.y, 3), round(t.theta, 3)),
            "distance": round(self.base.distance, 2),
            "collisions": self.base.collisions,
            "lms": None if self.lms is None else self.lms.state().scans_sent,
        }
