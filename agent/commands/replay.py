"""``loci replay``: run the agent's pipeline offline on a recording (the engine is
:mod:`agent.recording.offline`; this module is the command line around it).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agent.commands.options import positive_float, seconds
from agent.recording.offline import (
    FOREIGN_REORDER,
    read_recording_metadata,
    recorded_sync_params,
    replay_recording,
    summary_line,
)

if TYPE_CHECKING:
    from agent.core.pipeline import StepResult

log = logging.getLogger(__name__)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "replay",
        help="run the agent's pipeline on a recording and print/write the graph and areas",
        description=(
            "Replay an MCAP recording of a robot (loci run --record, loci record, or loci import) "
            "through the agent's pipeline: scans and odometry as recorded, the same odometry "
            "association, place classification, navigation graph and areas. Runs as fast as "
            "possible unless --realtime. A truncated file (crashed writer) is replayed up to its "
            "last complete message. The summary accounts for every scan in the file: processed, "
            "or not processed under a named reason."
        ),
        epilog=(
            "Examples:\n"
            "  loci replay run1.mcap --out-dir out/run1     "
            "# navgraph.json, graph.json, areas.json, places.jsonl, map.png,\n"
            "                                               # map.yaml + map.pgm, labels.png + labels.yaml\n"
            "  loci replay run1.mcap --places places.jsonl  # every loci.place/1 message, one per line\n"
            "  loci localize out/run1/map.yaml --recording run2.mcap --labels out/run1/labels.png"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", type=Path, metavar="IN.mcap", help="the recording")
    p.add_argument("--realtime", action="store_true", help="pace the messages at recorded speed")
    p.add_argument(
        "--speed",
        type=positive_float,
        metavar="FACTOR",
        help="pace the messages at FACTOR times recorded speed (--realtime is 1; default with "
        "--foxglove: 1, else as fast as possible)",
    )
    p.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve the replay live to the Foxglove app on this WebSocket port (docs/foxglove.md)",
    )
    p.add_argument(
        "--labels",
        type=Path,
        metavar="LABELS.yaml",
        help="with --foxglove: a labelled map (loci places label's YAML) to show as /labels",
    )
    p.add_argument(
        "--linger",
        type=seconds,
        metavar="SECONDS",
        help="with --foxglove: keep serving the final state this long after the end (default: until Ctrl-C)",
    )
    p.add_argument(
        "--out-dir",
        type=Path,
        metavar="DIR",
        help="write navgraph.json, graph.json, areas.json, places.jsonl, map.png (the path "
        "coloured by place label over a map built from the scans, with the graph and areas), and "
        "that map as map.yaml + map.pgm (map_server, loci localize) with its place labels as "
        "labels.png + labels.yaml (each free cell: the label of the nearest graph node along free "
        "cells) here",
    )
    p.add_argument(
        "--places",
        type=Path,
        metavar="FILE.jsonl",
        help="write every loci.place/1 message the replay publishes, one JSON object per line "
        "(stamp, label, probabilities, node, coverage, pose)",
    )
    p.add_argument("--json", action="store_true", help="print the graph, the areas and the counters as JSON")
    p.add_argument("--robot", help="the robot whose keys to replay (default: the recording's)")
    p.add_argument(
        "--model", type=Path, metavar="MODEL.npz", help="the place model (default: the recording's)"
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="take the pipeline and [odometry] parameters from this robot configuration instead of "
        "the recording",
    )
    p.add_argument(
        "--reorder",
        type=float,
        metavar="SECONDS",
        help="hold each scan this long so that late ones are put in stamp order (default: as "
        f"recorded by loci run; {FOREIGN_REORDER:g} s for other recordings)",
    )
    p.add_argument(
        "--fresh", action="store_true", help="start from an empty map even if the live run resumed one"
    )
    p.add_argument(
        "--duration",
        type=positive_float,
        metavar="SECONDS",
        help="replay only the first SECONDS of the recording",
    )
    p.set_defaults(handler=_replay)


def _replay(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from agent.config import load_config
    from agent.core.map_files import add_step, save_map
    from agent.core.odom_sync import SyncParams
    from agent.core.pipeline import PipelineParams, areas_message, graph_message, place_message
    from agent.progress import Progress
    from knowledge.fileio import atomic_write_text
    from knowledge.metric.mapping import ScanMapper
    from knowledge.places.model import PlaceModel
    from knowledge.topology import persistence

    config = load_config(args.config, env={}) if args.config else None
    params = PipelineParams.from_config(config) if config is not None else None
    sync = config.odometry.sync if config is not None else None
    if args.reorder is not None:
        base = sync or recorded_sync_params(read_recording_metadata(args.input)) or SyncParams()
        sync = replace(base, reorder=args.reorder)
    model = PlaceModel.load(args.model) if args.model else None
    want_places = args.places is not None or args.out_dir is not None
    places: list[str] = []
    mapper = ScanMapper() if args.out_dir is not None else None
    path: list[tuple[float, float, str | None]] = []

    live = _start_live(args)
    speed = args.speed if args.speed is not None else (1.0 if args.realtime or live is not None else None)
    held: dict[str, Any] = {}

    def on_pipeline(pipeline: Any) -> None:
        held["pipeline"] = pipeline
        if live is not None:
            live.mount = pipeline.params.mount
            live.on_state(*pipeline.messages())

    def on_step(result: StepResult) -> None:
        if live is not None:
            live.on_step(result)
            if result.graph_changed or result.areas_changed:
                live.on_state(*held["pipeline"].messages(result.stamp))
            else:
                live.tick()
        if want_places:
            places.append(json.dumps(place_message(result), separators=(",", ":")))
        if mapper is not None:
            add_step(mapper, result)
            path.append((result.pose.x, result.pose.y, result.label))

    try:
        with Progress(enabled=not args.quiet) as progress:
            res = replay_recording(
                args.input,
                robot=args.robot,
                model=model,
                params=params,
                sync=sync,
                speed=speed,
                fresh=args.fresh,
                on_step=on_step,
                progress=progress,
                on_pipeline=on_pipeline,
                duration=args.duration,
            )
        if live is not None:
            _linger(live, args.linger)
    finally:
        if live is not None:
            live.close()
    pipeline = res.pipeline
    doc = pipeline.state_document()
    stamp = pipeline.last_stamp or 0.0
    graph, areas = graph_message(doc, stamp), areas_message(doc, stamp)
    lines = "".join(line + "\n" for line in places)
    written: list[str] = []
    if args.places is not None:
        atomic_write_text(args.places, lines)
        written.append(str(args.places))
    if args.out_dir is not None:
        from agent.core.mapviz import render_layered_map

        out = args.out_dir
        atomic_write_text(out / "navgraph.json", persistence.dumps(doc) + "\n")
        atomic_write_text(out / "graph.json", json.dumps(graph, indent=1) + "\n")
        atomic_write_text(out / "areas.json", json.dumps(areas, indent=1) + "\n")
        atomic_write_text(out / "places.jsonl", lines)
        assert mapper is not None
        grid = mapper.grid(args.input.stem)
        render_layered_map(
            grid,
            graph,
            areas,
            out_png=out / "map.png",
            trajectory=path,
            title=f"{args.input.name}: {len(path)} scans, {len(graph['nodes'])} nodes, "
            f"{len(areas['areas'])} areas (path coloured by place label)",
        )
        save_map(out, grid, graph)
        written.append(
            f"{out}/navgraph.json, graph.json, areas.json, places.jsonl, map.png, map.yaml + map.pgm "
            f"(the occupancy map, frame {'map' if pipeline.tracker is not None else 'odom'}), "
            "labels.png + labels.yaml"
        )
    if res.truncated:
        print(
            f"{args.input}: the recording ends without its footer (its writer stopped early); "
            f"replayed up to its last complete message",
            file=sys.stderr,
        )
    summary = summary_line(args.input, res)
    if args.json:
        print(json.dumps({"graph": graph, "areas": areas, "stats": res.stats(), "truncated": res.truncated}))
        print(summary, file=sys.stderr)
    else:
        print(summary)
        for a in areas["areas"]:
            print(f"  area {a['id']}: {a['label'] or '?'} ({len(a['nodes'])} nodes)")
        for w in written:
            print(f"wrote {w}")
    return 0


def _start_live(args: argparse.Namespace) -> Any:
    """The Foxglove live view of ``--foxglove`` (None without it)."""
    if not args.foxglove:
        if args.labels is not None or args.linger is not None:
            raise SystemExit("loci replay: --labels and --linger go with --foxglove [HOST:]PORT")
        return None
    from agent.live.config import parse_address
    from agent.live.server import LabelledMap, LiveView

    try:
        host, port = parse_address(args.foxglove)
    except ValueError as exc:
        raise SystemExit(f"loci replay: --foxglove: {exc}") from None
    labels = LabelledMap.load(args.labels) if args.labels is not None else None
    live = LiveView(host, port, labels=labels, name=f"genius-loci replay {args.input.name}")
    print(f"Foxglove live view on {live.url} (open it in the Foxglove app)", file=sys.stderr, flush=True)
    return live


def _linger(live: Any, seconds: float | None) -> None:
    """Keep serving the final state for ``seconds`` (None: until Ctrl-C)."""
    import time

    if seconds is not None and seconds <= 0:
        return
    print(
        "replay done; serving the final state"
        + (f" for {seconds:g} s" if seconds is not None else " until Ctrl-C"),
        file=sys.stderr,
        flush=True,
    )
    end = time.monotonic() + (seconds if seconds is not None else float("inf"))
    try:
        while time.monotonic() < end:
            live.tick()
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
