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
import logging
import math
import signal
import sys
import threading
from types import FrameType
from typing import TYPE_CHECKING, Any

from agent.commands.options import add_bus_options, positive_float
from sim import WORLD_HELP

if TYPE_CHECKING:
    pass

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
    bus = BusConfig(
        mode=args.mode,
        listen=listen,
        connect=tuple(args.connect or (DEFAULT_AGENT_ENDPOINT,)),
        config_file=args.zenoh_config,
    )
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
    from agent.sim_node import run_robot

    return asyncio.run(run_robot(robot, name, bus, args.duration, tutor))
