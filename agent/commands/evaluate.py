"""``loci evaluate log``: replay a recording of a real log and score it against its truth.

The recording (``loci import`` of a CARMEN log or bag, or ``loci run --record``) is replayed
exactly as ``loci replay`` does it (:func:`agent.recording.offline.replay_recording`); each
processed scan's label, the final navigation graph and its areas are then scored by
:func:`knowledge.evaluation.real_logs.evaluate` against per-scan labels (``.npz``) or a
labelled map with the alignment of the log's frame to it. docs/real_logs.md describes the
truth formats and every score.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from knowledge.evaluation.real_logs import LogScores, Truth


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "evaluate",
        help="score what the agent makes of a real log against its ground truth",
        description="Score the agent on recorded real data. 'loci evaluate log' replays a recording "
        "and scores the place labels, navigation nodes, doorways and areas.",
    )
    sub = p.add_subparsers(dest="evaluate_command", metavar="WHAT", required=True)
    q = sub.add_parser(
        "log",
        help="replay a recording and score it against per-scan labels or a labelled map",
        description=(
            "Replay RECORDING through the agent's pipeline (as 'loci replay' does) and score it: "
            "per-scan room/corridor and 3-class accuracy (balanced accuracy, confusion matrix), "
            "per navigation node, doorways (each door the robot drove through: a doorway node within "
            "--door-radius; each doorway node: a labelled door that near) and areas against the rooms "
            "visited. LABELS is a per-scan label file (.npz: arrays t, pose, label, and optionally "
            "map_px, align) or a labelled map image (77 room, 115 corridor, 179 doorway, or codes 1-4) "
            "with --align; rooms and doors come from a labelled map (--label-map beside an .npz)."
        ),
        epilog=(
            "Example (the real Freiburg 079 log, data in ../shared/data/logs):\n"
            "  loci import freiburg-079-corrected.log.gz fr079.mcap\n"
            "  loci evaluate log fr079.mcap --labels fr079_labels_provisional.npz \\\n"
            "      --label-map Freiburg79_labels_provisional.png --out-dir out/fr079"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    q.add_argument("recording", type=Path, metavar="RECORDING.mcap", help="the recording to replay")
    q.add_argument(
        "--labels",
        type=Path,
        required=True,
        metavar="LABELS",
        help="per-scan labels (.npz) or a labelled map image (.png, with --align)",
    )
    q.add_argument(
        "--label-map",
        type=Path,
        metavar="MAP.png",
        help="the labelled map the .npz's map_px and align refer to (rooms and doors come from it)",
    )
    q.add_argument(
        "--align",
        type=Path,
        metavar="ALIGN.json",
        help="the transform from the log's metres to the map's pixels (rot_deg, m_per_px, tx_px, "
        "ty_px, mirror); needed with a labelled map image as LABELS, optional beside an .npz",
    )
    q.add_argument(
        "--model", type=Path, metavar="MODEL.npz", help="the place model (default: the recording's)"
    )
    q.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="pipeline and [odometry] parameters from this robot configuration",
    )
    q.add_argument("--robot", help="the robot whose keys to replay (default: the recording's)")
    q.add_argument(
        "--stamp-tolerance",
        type=float,
        default=0.01,
        metavar="S",
        help="seconds between a processed scan's stamp and its label's (default 0.01)",
    )
    q.add_argument(
        "--door-radius",
        type=float,
        default=0.7,
        metavar="M",
        help="metres between a door and its doorway node (default 0.7)",
    )
    q.add_argument(
        "--out-dir",
        type=Path,
        metavar="DIR",
        help="write scores.json, evaluation.png (path: dot = predicted label, ring = true label; "
        "doors and doorway nodes marked), places.jsonl, graph.json and areas.json here",
    )
    q.add_argument("--json", action="store_true", help="print the scores as one JSON object")
    q.set_defaults(handler=_evaluate_log)


def load_truth(labels: Path, label_map: Path | None, align: Path | None, poses: Any = None) -> Truth:
    """The truth of ``labels`` (see the module docstring); ``poses`` ``(stamps, (n, 3))`` of the
    replay are needed when ``labels`` is a labelled map image."""
    import cv2
    import numpy as np

    from knowledge.errors import DataError
    from knowledge.evaluation.real_logs import Alignment, LabelMap, Truth

    def image(path: Path) -> np.ndarray:
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None or img.ndim != 2:
            raise DataError(f"{path}: not a single-channel label image")
        return img

    def alignment() -> Alignment:
        assert align is not None
        try:
            return Alignment.from_json(json.loads(align.read_text()))
        except (OSError, json.JSONDecodeError) as exc:
            raise DataError(f"{align}: cannot read the alignment: {exc}") from exc

    if not labels.is_file():
        raise DataError(f"{labels}: no such label file")
    if labels.suffix == ".npz":
        try:
            with np.load(labels, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise DataError(f"{labels}: not a readable .npz label file ({exc})") from exc
        if align is not None:
            arrays["align"] = np.array(json.dumps(json.loads(align.read_text())))
        try:
            return Truth.from_npz(arrays, image(label_map) if label_map is not None else None)
        except ValueError as exc:
            raise DataError(f"{labels}: {exc}") from exc
    if align is None:
        raise DataError(f"{labels}: a labelled map needs --align (the log's metres to the map's pixels)")
    assert poses is not None
    stamps, xyt = poses
    return Truth.from_map(LabelMap.from_image(image(labels), alignment()), stamps, xyt)


def format_report(name: str, s: LogScores) -> str:
    """The scores as a few readable lines."""
    from knowledge.learning.metrics import format_confusion

    def pct(v: float | None) -> str:
        return "n/a" if v is None or v != v else f"{100 * v:.1f} %"

    two, three, d, a = s.two_class, s.three_class, s.doors, s.areas
    lines = [
        f"{name}: {s.scans_labelled} labelled scans"
        + (f" ({s.scans_in_span} in the replayed stretch)" if s.scans_in_span != s.scans_labelled else "")
        + f", {s.scans_scored} processed and scored",
        f"per scan, room/corridor: {pct(two.accuracy)} (balanced {pct(two.balanced_accuracy)}; "
        f"always {s.majority_class}: {pct(s.majority_two)})",
        f"per scan, 3 classes:     {pct(three.accuracy)} (balanced {pct(three.balanced_accuracy)})",
        format_confusion(three),
        f"per node (room/corridor, {s.nodes.n} place nodes scored, {s.nodes_unlabelled} unlabelled): "
        f"{pct(s.nodes.accuracy)} (balanced {pct(s.nodes.balanced_accuracy)})",
        f"doorways: {d['doors_found']} of {d['doors_driven_through']} doors driven through have a doorway "
        f"node within {d['radius']} m ({pct(d['recall'])}); {d['false_doorway_nodes']} of "
        f"{d['doorway_nodes']} doorway nodes have no door there ({pct(d['false_share'])} false); "
        f"{d['room_to_room_crossings']} room-to-room crossings not counted",
    ]
    if "rooms_visited" in a:
        lines.append(
            f"areas: {a['areas']}; {a['rooms_with_own_area']} of {a['rooms_visited']} rooms visited are "
            f"their own area ({pct(a['own_area_share'])}); over nodes: recall {pct(a['recall_mean'])}, "
            f"precision {pct(a['precision_mean'])} (mean per place / per area), pooled "
            f"{pct(a['recall_pooled'])} / {pct(a['precision_pooled'])}"
        )
    else:
        lines.append(f"areas: {a['areas']} ({a.get('note', '')})")
    return "\n".join(lines)


def _evaluate_log(args: argparse.Namespace) -> int:
    import numpy as np

    from agent.config import load_config
    from agent.core.map_files import add_step
    from agent.core.pipeline import PipelineParams, StepResult, areas_message, graph_message, place_message
    from agent.progress import Progress
    from agent.recording.offline import replay_recording
    from knowledge.evaluation.real_logs import evaluate
    from knowledge.fileio import atomic_write_text
    from knowledge.metric.mapping import ScanMapper
    from knowledge.places.model import PlaceModel

    config = load_config(args.config, env={}) if args.config else None
    params = PipelineParams.from_config(config) if config is not None else None
    sync = config.odometry.sync if config is not None else None
    model = PlaceModel.load(args.model) if args.model else None
    truth = None
    if args.labels.suffix == ".npz":  # fail before the replay on a bad label file
        truth = load_truth(args.labels, args.label_map, args.align)
    stamps: list[float] = []
    poses: list[tuple[float, float, float]] = []
    labels: list[str] = []
    places: list[str] = []
    mapper = ScanMapper() if args.out_dir is not None else None

    def on_step(result: StepResult) -> None:
        p = result.pose
        stamps.append(result.stamp)
        poses.append((p.x, p.y, p.theta))
        labels.append(result.label)
        if mapper is not None:
            places.append(json.dumps(place_message(result), separators=(",", ":")))
            add_step(mapper, result)

    with Progress(enabled=not args.quiet) as progress:
        res = replay_recording(
            args.recording,
            robot=args.robot,
            model=model,
            params=params,
            sync=sync,
            on_step=on_step,
            progress=progress,
        )
    doc = res.pipeline.state_document()
    stamp = res.pipeline.last_stamp or 0.0
    graph, areas = graph_message(doc, stamp), areas_message(doc, stamp)
    if truth is None:
        truth = load_truth(args.labels, args.label_map, args.align, (np.array(stamps), np.array(poses)))
    scores = evaluate(
        truth,
        np.array(stamps),
        labels,
        graph,
        areas,
        stamp_tolerance=args.stamp_tolerance,
        door_radius=args.door_radius,
    )
    out = {
        "recording": str(args.recording),
        "labels": str(args.labels),
        "replay": res.accounting(),
        **scores.as_dict(),
    }
    if args.out_dir is not None:
        from agent.core.mapviz import draw_doors, render_layered_map
        from knowledge.evaluation.real_logs import match_stamps

        d = args.out_dir
        atomic_write_text(d / "scores.json", json.dumps(out, indent=1) + "\n")
        atomic_write_text(d / "places.jsonl", "".join(line + "\n" for line in places))
        atomic_write_text(d / "graph.json", json.dumps(graph, indent=1) + "\n")
        atomic_write_text(d / "areas.json", json.dumps(areas, indent=1) + "\n")
        idx = match_stamps(truth.stamps, np.array(stamps), args.stamp_tolerance)
        true = [str(truth.labels[i]) if i >= 0 else None for i in idx]
        assert mapper is not None
        lm = render_layered_map(
            mapper.grid(args.recording.stem),
            graph,
            areas,
            trajectory=[(x, y, lab) for (x, y, _), lab in zip(poses, labels, strict=True)],
            truth=true,
            title=f"{args.recording.name}: dot = predicted label, ring = true label; doors: green found, "
            "red missed, grey not driven through, violet room to room",
        )
        draw_doors(lm, truth, graph, scores.doors)
        from knowledge.fileio import write_image

        write_image(d / "evaluation.png", lm.image)
    if args.json:
        print(json.dumps(out))
    else:
        print(format_report(args.recording.name, scores))
        if args.out_dir is not None:
            print(f"wrote {args.out_dir}/scores.json, evaluation.png, places.jsonl, graph.json, areas.json")
    return 0
