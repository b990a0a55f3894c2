"""``loci sim``: simulated devices that speak the same bytes as the real ones.

``loci sim lms`` starts a virtual SICK LMS 2xx on a pseudo-terminal and prints its device
path, so ``loci sick scan PATH`` (or the agent) talks to it as to a scanner on
``/dev/ttyUSB0``. It runs in the foreground until Ctrl-C.

``loci sim robot`` starts a whole simulated robot (:mod:`sim.robot`): a base driving
in a generated office or a map, a virtual LMS on a pty seeing from the base's true pose
(or a 360° laser publishing scans), optional people and camera. It joins the Zenoh bus and
prints the LMS device path and the robot's name (first two lines of standard output).

======================  ====================  =====================================
key                     payload               what
======================  ====================  =====================================
``loci/<r>/odom``       foxglove.PoseInFrame  odometry (frame odom), every step
``loci/<r>/sim/truth``  loci.truth/1          true pose, place class (evaluation)
``loci/<r>/base/status``  loci.base_status/1  goal active / reached / failed, collisions
``loci/<r>/scan``       foxglove.LaserScan    360° laser only (the LMS is on the pty)
``loci/<r>/camera``     foxglove.CompressedImage  with ``--camera``
``loci/<r>/base/cmd``   loci.twist/1          (subscribed) velocity commands
``loci/<r>/base/goal``  loci.base_goal/1      (subscribed) goals, paths, cancel
======================  ====================  =====================================
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
import sys
import threading
import uuid
from types import FrameType
from typing import TYPE_CHECKING, Any

from agent.commands.options import add_bus_options, positive_float
from sim import WORLD_HELP

if TYPE_CHECKING:
    import zenoh

    from agent.bus.bridge import Publisher
    from sim.robot import Goal, RobotSample, SimRobot, StatusReport

log = logging.getLogger(__name__)


def _pose(text: str) -> tuple[float, float, float]:
    try:
        x, y, th = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a pose is X,Y,HEADING (metres, metres, degrees); got {text!r}"
        ) from None
    return (x, y, math.radians(th))


def _route(text: str) -> tuple[tuple[float, float], ...]:
    try:
        pts = tuple((float(x), float(y)) for x, y in (p.split(",") for p in text.split(";") if p.strip()))
    except ValueError:
        pts = ()
    if not pts:
        raise argparse.ArgumentTypeError(f"a route is X,Y;X,Y;... in metres (map frame); got {text!r}")
    return pts


def register(subparsers: Any) -> None:
    from agent.commands.sick import parse_variant

    p = subparsers.add_parser(
        "sim",
        help="simulated devices (virtual LMS laser scanner, ...)",
        description="Simulated twins of the robot's devices; each speaks the same bytes as the real one.",
    )
    sub = p.add_subparsers(dest="sim_command", metavar="DEVICE", required=True)

    lms = sub.add_parser(
        "lms",
        help="a virtual SICK LMS 2xx on a pseudo-terminal",
        description=(
            "Start a virtual SICK LMS 2xx on a pseudo-terminal and print its device path (first "
            "line of standard output). It answers the initialisation telegrams as the real "
            "scanner does (9600 baud at power-up, baud changes, variant, configuration) and "
            "streams scans of a simulated world at the scanner's rate. Runs until Ctrl-C."
        ),
        epilog="Example: loci sim lms --world gen:3 --people 2   then, elsewhere:   loci sick scan PATH",
    )
    lms.add_argument(
        "--world",
        metavar="WORLD",
        help=f"what the scanner sees: {WORLD_HELP} (default: gen:0)",
    )
    lms.add_argument("--resolution", type=float, help="metres per cell of an image given as --world")
    lms.add_argument(
        "--rate",
        type=float,
        help="scans per second in continuous mode, e.g. 37.5 or 75 (default: the variant's, 37.5 for 180/0.5)",
    )
    lms.add_argument(
        "--link",
        metavar="PATH",
        help="publish the device as a symlink at PATH (default: a new temporary directory)",
    )
    lms.add_argument(
        "--variant",
        type=parse_variant,
        default="180/0.5",
        help="power-up scan angle/resolution in degrees (default: 180/0.5)",
    )
    lms.add_argument("--units", choices=("cm", "mm"), default="cm", help="measured-value units (default: cm)")
    lms.add_argument(
        "--pose", type=_pose, help="sensor pose X,Y,HEADING (m, m, degrees; default: near the map centre)"
    )
    lms.add_argument(
        "--noise", type=float, default=0.01, help="range noise standard deviation in metres (default: 0.01)"
    )
    lms.add_argument("--people", type=int, default=0, help="people walking around the sensor (default: 0)")
    lms.add_argument("--seed", type=int, default=0, help="random seed for noise and people (default: 0)")
    lms.set_defaults(handler=_lms)
    _register_robot(sub)


def _register_robot(sub: Any) -> None:
    from agent.commands.sick import parse_variant

    r = sub.add_parser(
        "robot",
        help="a simulated robot on the bus: base, LMS on a pty, people, camera",
        description=(
            "Start a simulated robot: a differential-drive base in a generated office (or a map), a "
            "virtual SICK LMS 2xx on a pseudo-terminal whose pose follows the base's true pose, and "
            "optionally walking people and a camera. It joins the Zenoh bus, publishes odometry "
            "(loci/ROBOT/odom), the true pose (loci/ROBOT/sim/truth) and status reports "
            "(loci/ROBOT/base/status), and obeys velocity commands (base/cmd) and goals (base/goal). "
            "Prints the LMS device path and the robot name (first two lines), then runs until Ctrl-C."
        ),
        epilog=(
            "Examples: loci sim robot --world gen:3 --tour --loop;   "
            "loci sim robot --route '10,10;14,10;14,12' --speed 4 --laser 360"
        ),
    )
    r.add_argument(
        "--world",
        metavar="WORLD",
        default="gen:0",
        help=f"{WORLD_HELP}; demo:SEED starts at the tour's charging station (default: gen:0)",
    )
    r.add_argument("--resolution", type=float, help="metres per cell of an image given as --world")
    add_bus_options(r, mode=True)
    r.add_argument(
        "--laser",
        choices=("front", "360"),
        default="front",
        help="front: a 180° LMS 2xx on a pty (default); 360: a 360° laser publishing on loci/ROBOT/scan",
    )
    r.add_argument(
        "--mount",
        type=_pose,
        help="the laser on the robot: X,Y,YAW (m forward, m left, degrees; default 0,0,0)",
    )
    r.add_argument(
        "--link", metavar="PATH", help="publish the LMS as a symlink at PATH (default: a temporary directory)"
    )
    r.add_argument(
        "--variant",
        type=parse_variant,
        default="180/0.5",
        help="LMS power-up angle/resolution (default: 180/0.5)",
    )
    r.add_argument(
        "--units", choices=("cm", "mm"), default="cm", help="LMS measured-value units (default: cm)"
    )
    r.add_argument(
        "--lms-rate", type=positive_float, help="LMS scans per second (default: the variant's, 37.5 Hz)"
    )
    r.add_argument("--beams", type=int, default=360, help="beams of the 360° laser (default: 360)")
    r.add_argument(
        "--scan-rate", type=positive_float, default=10.0, help="360° scans per simulated second (default: 10)"
    )
    r.add_argument(
        "--noise", type=float, default=0.01, help="range noise standard deviation, metres (default: 0.01)"
    )
    r.add_argument("--people", type=int, default=0, help="people walking near the start (default: 0)")
    r.add_argument("--camera", action="store_true", help="publish JPEG camera frames on loci/ROBOT/camera")
    r.add_argument(
        "--camera-rate", type=positive_float, default=2.0, help="camera frames per second (default: 2)"
    )
    r.add_argument(
        "--start",
        type=_pose,
        help="true start pose X,Y,HEADING (m, m, degrees; default: on the route or in a corridor)",
    )
    r.add_argument(
        "--route", type=_route, help="drive through these map-frame points: 'X,Y;X,Y;...' (metres)"
    )
    r.add_argument(
        "--tour", action="store_true", help="drive a tour of the building's rooms through their doors"
    )
    r.add_argument("--rooms", type=int, help="with --tour: visit at most this many rooms, the nearest first")
    r.add_argument("--loop", action="store_true", help="drive the route or tour again and again")
    r.add_argument(
        "--speed",
        type=positive_float,
        default=1.0,
        help="simulated seconds per wall-clock second (default: 1, real time)",
    )
    r.add_argument(
        "--odom-rate",
        type=positive_float,
        default=50.0,
        help="odometry samples per simulated second (default: 50)",
    )
    r.add_argument(
        "--odom-start",
        type=_pose,
        help="the odometry's start pose X,Y,HEADING (default: the true start pose; 0,0,0 like a real base)",
    )
    r.add_argument(
        "--exact-odometry", action="store_true", help="odometry without drift (equal to the true pose)"
    )
    r.add_argument(
        "--cmd-timeout",
        type=positive_float,
        default=1.0,
        help="stop when no velocity command came for this many simulated seconds (default: 1)",
    )
    r.add_argument(
        "--duration",
        type=positive_float,
        metavar="S",
        help="stop after S wall-clock seconds (default: Ctrl-C)",
    )
    r.add_argument("--seed", type=int, default=0, help="random seed for noise and people (default: 0)")
    r.add_argument(
        "--tutor",
        action="store_true",
        help="with --world demo:SEED: the guided tour's tutor, walking the legs it is told on "
        "loci/ROBOT/sim/tutor and publishing where it is on loci/ROBOT/sim/tutor/state (docs/demo.md)",
    )
    r.add_argument(
        "--tutor-speed",
        type=positive_float,
        default=0.6,
        help="the tutor's walking speed, m/s (default: 0.6)",
    )
    r.set_defaults(handler=_robot)


def _lms(args: argparse.Namespace) -> int:
    from drivers.sim.lms import VirtualLMS
    from sim.lms_world import LmsWorld, default_sensor_pose, load_world_grid, people_in

    grid = load_world_grid(args.world, args.resolution)
    pose = args.pose or default_sensor_pose(grid)
    legs = people_in(grid, (pose[0], pose[1]), args.people, seed=args.seed)
    world = LmsWorld(grid, pose, legs, noise_std=args.noise, seed=args.seed)
    angle, res = args.variant
    sim = VirtualLMS(
        world, link=args.link, rate=args.rate, angle=angle, resolution=res, units=args.units, seed=args.seed
    )
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        path = sim.start()
        print(path, flush=True)
        print(
            f"virtual LMS on {path} -> {sim.pts}: {angle}°/{res:g}°, {args.units}, 9600 baud at power-up, "
            f"world {grid.name} ({grid.shape[1]}x{grid.shape[0]} cells at {grid.resolution} m), "
            f"sensor at ({pose[0]:.2f}, {pose[1]:.2f}, {math.degrees(pose[2]):.0f}°); Ctrl-C to stop",
            file=sys.stderr,
            flush=True,
        )
        while not stop.wait(0.5):
            pass
    finally:
        sim.stop()
        for s, h in previous.items():
            signal.signal(s, h)
    st = sim.state()
    print(
        f"virtual LMS stopped: {st.scans_sent} scans sent, {st.requests} requests answered", file=sys.stderr
    )
    return 0


# ---------------------------------------------------------------------------- loci sim robot
def _robot(args: argparse.Namespace) -> int:
    from agent.bus.keys import robot_name
    from agent.bus.session import DEFAULT_AGENT_ENDPOINT, BusConfig
    from drivers.sim.base import OdometryNoise
    from sim.robot import Mount, SimRobot, SimRobotConfig

    name = robot_name(args.robot)
    listen = tuple(args.listen or ()) if args.mode == "client" else tuple(args.listen or ("tcp/127.0.0.1:0",))
    bus = BusConfig(mode=args.mode, listen=listen, connect=tuple(args.connect or (DEFAULT_AGENT_ENDPOINT,)))
    config = SimRobotConfig(
        world=args.world,
        resolution=args.resolution,
        start=args.start,
        laser=args.laser,
        mount=Mount(*args.mount) if args.mount else Mount(),
        link=args.link,
        lms_rate=args.lms_rate,
        lms_variant=args.variant,
        lms_units=args.units,
        beams=args.beams,
        scan_rate=args.scan_rate,
        noise=args.noise,
        people=args.people,
        camera=args.camera,
        camera_rate=args.camera_rate,
        odom_rate=args.odom_rate,
        speed=args.speed,
        route=args.route or (),
        tour=args.tour,
        tour_rooms=args.rooms,
        loop=args.loop,
        odom_noise=OdometryNoise(0.0, 0.0, 0.0) if args.exact_odometry else OdometryNoise(),
        odom_start=args.odom_start,
        cmd_timeout=args.cmd_timeout,
        seed=args.seed,
    )
    robot = SimRobot(config)
    tutor = None
    if args.tutor:
        from agent.demo.tutor_control import TutorControl
        from knowledge.errors import ConfigError

        if robot.tour is None:
            raise ConfigError("--tutor needs the guided tour's world: --world demo:SEED")
        tutor = TutorControl(robot.tour, speed=args.tutor_speed)
        tutor.attach(robot)
    return asyncio.run(_run_robot(robot, name, bus, args.duration, tutor))


async def _run_robot(robot: SimRobot, name: str, bus: Any, duration: float | None, tutor: Any = None) -> int:
    from agent.bus.bridge import BusClosed, subscribe_stream
    from agent.bus.session import bus_session

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        with bus_session(bus) as session:
            node = _RobotNode(session, name, robot)
            cmds = subscribe_stream(session, name, "base/cmd")
            goals = subscribe_stream(session, name, "base/goal")

            async def obey_commands() -> None:
                with contextlib.suppress(BusClosed):
                    while True:
                        msg = await cmds.recv()
                        robot.command_velocity(float(msg["v"]), float(msg["omega"]))

            async def obey_goals() -> None:
                with contextlib.suppress(BusClosed):
                    while True:
                        msg = await goals.recv()
                        if msg.get("cancel"):
                            robot.cancel()
                        else:
                            robot.send_goal(goal_from_message(msg))

            tasks = [asyncio.create_task(obey_commands()), asyncio.create_task(obey_goals())]
            if tutor is not None:
                tasks.append(asyncio.create_task(_serve_tutor(session, name, tutor)))
            try:
                path = robot.start()
                print(path if path is not None else "-", flush=True)
                print(name, flush=True)
                c = robot.config
                where = robot.base.true_pose
                print(
                    f"simulated robot {name!r} in {robot.grid.name}: "
                    f"{'LMS on ' + str(path) if path else '360° laser on loci/' + name + '/scan'}, "
                    f"start ({where.x:.2f}, {where.y:.2f}, {math.degrees(where.theta):.0f}°), "
                    f"{'tour of ' + str(len(robot.route.visits)) + ' rooms, ' if c.tour and robot.route else ''}"
                    f"{'route of ' + format(robot.route.length, '.1f') + ' m, ' if robot.route else ''}"
                    f"speed x{c.speed:g}; bus connect {', '.join(bus.connect)}; Ctrl-C to stop",
                    file=sys.stderr,
                    flush=True,
                )
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), duration)
            finally:
                robot.stop()
                cmds.close()
                goals.close()
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
                node.close()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    st = robot.state()
    print(
        f"simulated robot stopped after {st['time']:.1f} simulated s: {st['distance']:.1f} m driven, "
        f"{st['collisions']} collisions, {st['lms'] or 0} LMS scans sent",
        file=sys.stderr,
    )
    return 0


async def _serve_tutor(session: zenoh.Session, name: str, tutor: Any, period: float = 0.2) -> None:
    """Obey ``loci/<r>/sim/tutor`` commands and publish the tutor's state every ``period`` s."""
    import zenoh

    from agent.demo import messages

    def on_cmd(sample: zenoh.Sample) -> None:
        try:
            tutor.command(messages.decode(sample.payload.to_bytes()))
        except ValueError as exc:
            log.warning("sim/tutor: ignored a command: %s", exc)

    sub = session.declare_subscriber(messages.tutor_cmd_key(name), on_cmd)
    pub = session.declare_publisher(
        messages.tutor_state_key(name), encoding=zenoh.Encoding(messages.ENCODING)
    )
    try:
        while True:
            pub.put(messages.encode(tutor.state()))
            await asyncio.sleep(period)
    finally:
        with contextlib.suppress(zenoh.ZError):
            sub.undeclare()
            pub.undeclare()


def goal_from_message(msg: dict[str, Any]) -> Goal:
    """A ``loci.base_goal/1`` message (validated) as a :class:`~sim.robot.Goal`."""
    from sim.robot import Goal

    points = [msg["goal"]] if msg.get("goal") is not None else list(msg["path"])
    heading = points[-1].get("theta")
    return Goal(
        id=str(msg.get("id") or f"goal-{uuid.uuid4().hex[:12]}"),
        points=tuple((float(p["x"]), float(p["y"])) for p in points),
        heading=None if heading is None else float(heading),
        frame_id=str(msg.get("frame_id", "odom")),
        plan=bool(msg.get("plan", True)),
    )


class _RobotNode:
    """Publishes what a :class:`~sim.robot.SimRobot` produces (called on its threads)."""

    def __init__(self, session: zenoh.Session, name: str, robot: SimRobot) -> None:
        from agent.bus.bridge import publish_stream

        self.odom: Publisher[Any] = publish_stream(session, name, "odom")
        self.truth: Publisher[Any] = publish_stream(session, name, "sim/truth")
        self.status: Publisher[Any] = publish_stream(session, name, "base/status")
        self.pubs = [self.odom, self.truth, self.status]
        robot.sample_listeners.append(self.on_sample)
        robot.status_listeners.append(self.on_status)
        if robot.config.laser == "360":
            self.scan = publish_stream(session, name, "scan")
            self.pubs.append(self.scan)
            robot.scan_listeners.append(self.scan.put)
        if robot.camera is not None:
            self.camera = publish_stream(session, name, "camera")
            self.pubs.append(self.camera)
            robot.frame_listeners.append(self.camera.put)

    def on_sample(self, s: RobotSample) -> None:
        self.odom.put(s.odom)
        self.truth.put(truth_message(s))

    def on_status(self, r: StatusReport) -> None:
        self.status.put(status_message(r))

    def close(self) -> None:
        for p in self.pubs:
            p.close()


def truth_message(s: RobotSample) -> dict[str, Any]:
    """A ``loci.truth/1`` message of one simulation step."""
    t, o = s.truth, s.odom
    return {
        "schema": "loci.truth/1",
        "stamp": s.stamp,
        "x": t.x,
        "y": t.y,
        "theta": t.theta,
        "frame_id": t.frame_id,
        "odom": {"x": o.x, "y": o.y, "theta": o.theta},
        "space": s.space,
        "label": s.label,
        "collisions": s.collisions,
    }


def status_message(r: StatusReport) -> dict[str, Any]:
    """A ``loci.base_status/1`` message of a status report."""
    return {
        "schema": "loci.base_status/1",
        "stamp": r.stamp,
        "status": r.status,
        "goal": r.goal,
        "reason": r.reason,
        "pose": {"x": r.odom.x, "y": r.odom.y, "theta": r.odom.theta},
        "distance": r.distance,
    }
