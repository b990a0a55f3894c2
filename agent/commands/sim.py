"""``loci sim``: simulated devices that speak the same bytes as the real ones.

``loci sim lms`` starts a virtual SICK LMS 2xx on a pseudo-terminal and prints its device
path, so ``loci sick scan PATH`` (or the agent) talks to it as to a scanner on
``/dev/ttyUSB0``. It runs in the foreground until Ctrl-C.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
from types import FrameType
from typing import Any


def _pose(text: str) -> tuple[float, float, float]:
    try:
        x, y, th = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a pose is X,Y,HEADING (metres, metres, degrees); got {text!r}"
        ) from None
    return (x, y, math.radians(th))


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
        metavar="MAP",
        help="what the scanner sees: a map_server .yaml, an image (with --resolution), or gen:SEED "
        "for a generated office (default: gen:0)",
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


def _lms(args: argparse.Namespace) -> int:
    from drivers.sim.lms import VirtualLMS
    from drivers.sim.lms_world import LmsWorld, default_sensor_pose, load_world_grid, people_in

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
