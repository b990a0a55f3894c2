"""``loci run``: the agent on a robot (laser, odometry, place classification, maps, bus).

Reads the TOML configuration (docs/agent.md lists every key), runs until Ctrl-C or SIGTERM
and exits 0 after an orderly shutdown (laser stopped, state saved, recording closed, every
Zenoh session closed). The last line on standard error is the run's summary as JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "run",
        help="run the agent: classify places from the laser, build the navigation graph and areas",
        description=(
            "Run the genius-loci agent: read the laser (a SICK LMS 2xx on a serial port, or scans "
            "from the bus) and the odometry (loci/ROBOT/odom), label every scan (room, corridor, "
            "doorway, hallway), build the navigation graph and its areas, publish them on the Zenoh "
            "bus, answer state queries, and keep the map across restarts. Stops on Ctrl-C or SIGTERM."
        ),
        epilog=(
            "Examples:\n"
            "  loci run --config deploy/robot.toml --record 'runs/%%Y%%m%%d-%%H%%M%%S.mcap' --foxglove 8765\n"
            "  loci run --config robot.toml --play run.mcap   # the live agent on a recording, at recorded speed"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="the robot's TOML configuration (default: $LOCI_CONFIG, else built-in defaults)",
    )
    p.add_argument("--robot", help="the robot's name, the second chunk of its keys (overrides [robot] name)")
    p.add_argument(
        "--record",
        metavar="OUT.mcap",
        help="record loci/ROBOT/** into this MCAP file (overrides [record] path; strftime codes expand)",
    )
    p.add_argument(
        "--state-dir", type=Path, metavar="DIR", help="where the map persists (overrides [state] dir)"
    )
    p.add_argument("--model", metavar="MODEL.npz", help="the place model (overrides [places] model)")
    p.add_argument(
        "--play",
        metavar="IN.mcap",
        help="take the scans and the odometry from this recording instead of the robot's devices, "
        "through the live agent at recorded speed ([laser] source = 'recording'); it stops at the end",
    )
    p.add_argument(
        "--speed",
        type=float,
        metavar="FACTOR",
        help="with --play: FACTOR times recorded speed (default 1)",
    )
    p.add_argument(
        "--duration",
        type=float,
        metavar="SECONDS",
        help="with --play: only the first SECONDS of the recording",
    )
    p.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve the live view to the Foxglove app on this WebSocket port (host 127.0.0.1 unless "
        "given; overrides [foxglove] listen; docs/foxglove.md)",
    )
    p.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from agent.config import load_config

    config = load_config(
        args.config,
        overrides={
            "robot.name": args.robot,
            "record.path": args.record,
            "state.dir": args.state_dir,
            "places.model": args.model,
            "foxglove.listen": args.foxglove,
            "laser.source": "recording" if args.play else None,
            "laser.recording": args.play,
            "laser.speed": args.speed,
            "laser.duration": args.duration,
        },
    )
    return asyncio.run(_main(config))


async def _main(config: Any) -> int:
    from agent.runtime import Agent

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)

    def ready(agent: Agent) -> None:
        laser = {
            "lms": f"LMS on {config.laser.port}",
            "recording": f"the recording {config.laser.recording} (scans and odometry)",
        }.get(config.laser.source, f"scans from {agent.keys.scan}")
        parts = [
            f"laser: {laser}",
            f"odometry: {agent.keys.odom}",
            f"bus: {', '.join(agent.endpoints) or config.bus.mode}",
            f"state: {config.state.path}",
        ]
        if agent.report.recording:
            parts.append(f"recording: {agent.report.recording}")
        if agent.live is not None:
            parts.append(f"Foxglove: {agent.live.url}")
        print(
            f"running robot {agent.robot} ({'; '.join(parts)}); Ctrl-C to stop", file=sys.stderr, flush=True
        )

    try:
        report = await Agent(config, on_ready=ready).run(stop)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    print(
        f"stopped: {report.scans_processed} scans processed, {report.dropped} dropped, "
        f"{report.nodes} nodes, {report.areas} areas, state saved to {report.state_file}",
        file=sys.stderr,
    )
    print("summary: " + json.dumps(report.as_dict(), sort_keys=True), file=sys.stderr, flush=True)
    return 0
