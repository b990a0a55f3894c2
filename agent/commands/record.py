"""``loci record``: record every sample of a robot's keys into an MCAP file.

A standalone recorder process: it joins the bus as a peer (connecting to the agent's
endpoint), subscribes ``loci/<robot>/**`` and writes each sample with its schema, until
Ctrl-C, SIGTERM or ``--duration``. The file opens in Foxglove.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
from pathlib import Path
from typing import Any

from agent.commands.options import add_bus_options, positive_seconds


def register(subparsers: Any) -> None:
    from agent.bus.session import DEFAULT_AGENT_ENDPOINT

    p = subparsers.add_parser(
        "record",
        help="record a robot's bus traffic into an MCAP file (opens in Foxglove)",
        description=(
            "Join the Zenoh bus, subscribe to every key of the robot (loci/ROBOT/**) and write each "
            "sample with its schema into an MCAP file: laser scans, poses, images and scene updates as "
            "Foxglove protobuf, the rest as JSON with a JSON Schema. Runs until Ctrl-C, SIGTERM or "
            "--duration; the file is flushed every second, so even a killed recorder leaves a "
            "readable file (loci replay reads it up to the last complete chunk). When nothing was "
            "published on the robot's keys, no file is left and the exit status is 1."
        ),
        epilog=(
            f"Example: loci record run1.mcap --robot rosie --connect {DEFAULT_AGENT_ENDPOINT} --duration 60\n"
            "On a robot with the router (docs/deploy.md): loci record run1.mcap --robot rosie "
            "--mode client --zenoh-config /etc/loci/zenoh/tools.json5"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("output", metavar="OUT.mcap", help="the recording to write (a file)")
    add_bus_options(p, mode=True)
    p.add_argument(
        "--duration", type=positive_seconds, metavar="S", help="stop after S seconds (default: until Ctrl-C)"
    )
    p.add_argument(
        "--flush",
        type=positive_seconds,
        default=1.0,
        metavar="S",
        help="flush to the file every S seconds (default: 1)",
    )
    p.add_argument("--force", action="store_true", help="overwrite OUT.mcap if it exists")
    p.set_defaults(handler=_record)


def _record(args: argparse.Namespace) -> int:
    from agent.bus.keys import robot_name
    from agent.bus.session import DEFAULT_AGENT_ENDPOINT, BusConfig

    robot = robot_name(args.robot)
    if args.mode == "client":
        listen: tuple[str, ...] = tuple(args.listen or ())
    else:
        listen = tuple(args.listen or ("tcp/127.0.0.1:0",))
    config = BusConfig(
        mode=args.mode,
        listen=listen,
        connect=tuple(args.connect or (DEFAULT_AGENT_ENDPOINT,)),
        config_file=args.zenoh_config,
    )
    return asyncio.run(_run(args, robot, config))


async def _run(args: argparse.Namespace, robot: str, config: Any) -> int:
    from agent.bus.keys import robot_wildcard
    from agent.bus.session import bus_session
    from agent.recording.recorder import McapSink, Recorder, recording_metadata

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    key = robot_wildcard(robot)
    sink = McapSink(args.output, overwrite=args.force, metadata=recording_metadata(robot, key=key))
    try:
        with bus_session(config) as session:
            recorder = Recorder(session, sink, key, flush_interval=args.flush)
            task = asyncio.create_task(recorder.run())
            print(
                f"recording {key} into {args.output} (connect {', '.join(config.connect)}); Ctrl-C to stop",
                file=sys.stderr,
                flush=True,
            )
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), args.duration)
            recorder.stop()
            await task
            stats = recorder.stats
    finally:
        sink.close()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    if sink.messages == 0:
        Path(args.output).unlink(missing_ok=True)
        print(
            f"loci record: nothing was published on {key} (is the agent running, robot {robot!r}, "
            f"reachable at {', '.join(config.connect)}?); no file written",
            file=sys.stderr,
        )
        return 1
    print(
        f"recorded {sink.messages} messages into {args.output} "
        f"({stats['dropped']} dropped, {stats['invalid']} invalid)",
        file=sys.stderr,
    )
    return 0
