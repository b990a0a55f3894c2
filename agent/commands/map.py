"""``loci map save``: ask a running agent to save the occupancy map it builds, over Zenoh.

The request (``loci.map_save/1``) goes to the agent's ``loci/<robot>/map/save`` queryable;
the agent writes ``map.yaml`` + ``map.pgm`` and ``labels.png`` + ``labels.yaml``
(:mod:`agent.core.map_files`) and answers where (``loci.map_saved/1``) or why not
(``loci.error/1``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from agent.commands.options import add_bus_options, add_json_option, emit_json, positive_seconds

#: Seconds to wait for the agent's answer (a large map takes a few seconds to label and write).
DEFAULT_TIMEOUT = 30.0


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "map",
        help="the running agent's occupancy map: save it as map_server files",
        description="Talk to a running agent (loci run) about the occupancy map it builds.",
    )
    sub = p.add_subparsers(dest="map_command", metavar="COMMAND", required=True)
    save = sub.add_parser(
        "save",
        help="save the running agent's occupancy map and place labels into a folder",
        description=(
            "Ask the agent on the bus (loci/ROBOT/map/save) to write the occupancy map it has built "
            "from the scans of this run as map.yaml + map.pgm (map_server: loci localize and nav2's "
            "map_server load it) and its place labels as labels.png + labels.yaml, into DIR. DIR is "
            "a folder on the agent's computer (made if missing); a relative DIR is taken from this "
            "command's working directory. A folder that already holds a saved map is left alone "
            "unless --overwrite."
        ),
        epilog=(
            "Examples:\n"
            "  loci map save --out /data/maps/floor2 --robot rosie\n"
            "  loci map save --out maps/today --overwrite --connect tcp/192.168.1.20:7447\n"
            "  loci localize /data/maps/floor2/map.yaml --recording run.mcap --labels /data/maps/floor2/labels.png"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    save.add_argument("--out", type=Path, required=True, metavar="DIR", help="the folder to save the map in")
    save.add_argument(
        "--overwrite", action="store_true", help="replace a map saved in DIR before (default: refuse)"
    )
    save.add_argument(
        "--timeout",
        type=positive_seconds,
        default=DEFAULT_TIMEOUT,
        metavar="S",
        help=f"seconds to wait for the agent's answer (default {DEFAULT_TIMEOUT:g})",
    )
    add_json_option(save, help="print the agent's answer (loci.map_saved/1) as one JSON object")
    add_bus_options(save)
    save.set_defaults(handler=_save)


def _save(args: argparse.Namespace) -> int:
    import time

    from agent.bus.keys import REQUEST_KEYS, robot_name, stream_key
    from agent.bus.queryable import request
    from agent.bus.session import DEFAULT_AGENT_ENDPOINT, BusConfig, BusError, bus_session
    from knowledge.errors import MapError

    robot = robot_name(args.robot)
    key = stream_key(robot, "map/save")
    schema, _ = REQUEST_KEYS["map/save"]
    message = {
        "schema": schema,
        "dir": str(args.out.absolute()),
        "overwrite": args.overwrite,
        "stamp": time.time(),
    }
    config = BusConfig(
        listen=tuple(args.listen or ("tcp/127.0.0.1:0",)),
        connect=tuple(args.connect or (DEFAULT_AGENT_ENDPOINT,)),
        config_file=args.zenoh_config,
    )
    with bus_session(config) as session:
        replies = request(session, key, message, schema, timeout=args.timeout)
    if not replies:
        raise BusError(
            f"no agent answered on {key} within {args.timeout:g} s: is loci run running for robot "
            f"{robot!r}, and does --connect name its endpoint ({', '.join(config.connect)})?"
        )
    reply = replies[0]
    if reply.value is None:
        raise MapError(f"the agent did not save the map: {reply.error}")
    saved = reply.value
    if args.json:
        emit_json(saved)
        return 0
    print(
        f"saved the map of {robot} in {saved['dir']}: {saved['width']} x {saved['height']} cells of "
        f"{saved['resolution']:g} m, frame {saved['frame_id']}, origin {saved['origin']}, {saved['scans']} scans"
    )
    for f in saved["files"]:
        print(f"  {f}")
    return 0
