"""``loci places topology`` and ``loci places segment-score``: topological maps from occupancy maps.

``topology`` runs the whole chain of :mod:`knowledge.topology.pipeline` on one map and
writes every intermediate result; ``segment-score`` scores a room segmentation against a
hand-made ground truth so anyone can check a result. Both are registered under ``loci places``
by :mod:`agent.commands.places`.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

from agent.commands.options import emit_json, pct

log = logging.getLogger("loci.places.topology")

#: Files ``loci places topology`` writes into ``--out-dir``.
OUTPUT_FILES = {
    "labels": "labels.png",
    "relaxed": "relaxed.png",
    "corrected": "corrected.png",
    "regions": "regions.png",
    "segments": "segments.png",
    "graph": "topomap.json",
    "overview": "overview.png",
}

_SEGMENT_CLASSES = ("room", "corridor", "hallway")


def register_topology_commands(psub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``topology`` and ``segment-score`` to the ``loci places`` sub-commands."""
    t = psub.add_parser(
        "topology",
        help="topological map of an occupancy map: labels, relaxation, regions, region graph",
        description="Label every free cell of a map with a place model, smooth the labels by probabilistic\n"
        "relaxation (book Sect. 4.5), cut the map into regions, correct small and lonely regions\n"
        "(Sect. 4.7) and build the region graph. Writes into DIR:\n"
        "  labels.png     label codes before relaxation (8-bit: 0 none, 1 room, 2 corridor, 3 doorway, 4 hallway)\n"
        "  relaxed.png    label codes after relaxation\n"
        "  corrected.png  label codes after the region correction\n"
        "  regions.png    region ids (16-bit; the node ids of topomap.json; 0 = no region)\n"
        "  segments.png   room segments (16-bit region ids of the room/corridor/hallway regions, the other\n"
        "                 free cells grown into them; input for 'loci places segment-score')\n"
        "  topomap.json   the topological map (schema loci.topomap/1, see docs/topology.md)\n"
        "  overview.png   the labels before and after, the regions and the graph, with a legend\n"
        "and beside each of the five images its map_server YAML (labels.yaml, ...; mode raw, the\n"
        "input map's resolution and origin), so they load as map layers in ROS and Foxglove.",
        epilog="Example: loci places topology lab_intel.png --resolution 0.05 --free-grey 250 --out-dir out/intel",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    t.add_argument("map", type=Path, metavar="MAP", help="map_server YAML, or an image with --resolution")
    t.add_argument("--resolution", type=float, metavar="M", help="metres per cell for image maps (e.g. 0.05)")
    t.add_argument(
        "--free-grey",
        type=int,
        default=None,
        metavar="G",
        help="for image maps: cells with grey value >= G are free, all others occupied "
        "(the IPA segmentation maps: 250); default: map_server thresholds",
    )
    t.add_argument(
        "--model",
        type=Path,
        default=None,
        help="a place model (default: the bundled map model, default_map.npz)",
    )
    t.add_argument(
        "--out-dir", type=Path, required=True, metavar="DIR", help="the folder to write the outputs into"
    )
    t.add_argument(
        "--iterations", type=int, default=50, help="relaxation iterations (default 50, the book's)"
    )
    t.add_argument("--no-correction", action="store_true", help="skip the heuristic region correction")
    t.add_argument(
        "--place-min-area",
        type=float,
        default=None,
        metavar="M2",
        help="rooms/corridors of at most this area are merged (default: the model's, else 1 m²)",
    )
    t.add_argument(
        "--doorway-min-area",
        type=float,
        default=None,
        metavar="M2",
        help="doorways of at most this area are merged (default: the model's, else 0.1 m²)",
    )
    t.add_argument(
        "--no-grow",
        action="store_true",
        help="segments.png holds only the room/corridor/hallway regions (doorway cells stay 0)",
    )
    t.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    t.set_defaults(handler=cmd_topology)

    s = psub.add_parser(
        "segment-score",
        help="recall and precision of a room segmentation against a ground-truth segmentation",
        description="Score a room segmentation (Bormann et al., ICRA 2016). Each 8-connected region of\n"
        "grey >= 250 in GT_SEGMENTATION.png (doorways closed by black lines) is a room; rooms and\n"
        "segments of <= 100 pixels are ignored. Recall of a room = its largest overlap with a segment\n"
        "over its size; precision of a segment = its largest overlap with a room over its size; both\n"
        "as the mean over rooms/segments and pixel-pooled.\n\n"
        "SEGMENTS.png: segment ids (8/16-bit grey, 0 = none, e.g. segments.png of 'loci places\n"
        "topology') or a colour picture (one segment per colour, black = none). With --graph, only the\n"
        "ids of nodes labelled room, corridor or hallway in that topomap.json count (use it with\n"
        "regions.png to score the bare regions, doorway regions excluded).",
        epilog="Example: loci places segment-score out/intel/segments.png lab_intel_gt_segmentation.png",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    s.add_argument("segments", type=Path, metavar="SEGMENTS.png", help="the segmentation to score")
    s.add_argument("gt", type=Path, metavar="GT_SEGMENTATION.png", help="the ground-truth segmentation")
    s.add_argument(
        "--graph",
        type=Path,
        default=None,
        metavar="TOPOMAP.json",
        help="count only the ids of room/corridor/hallway nodes of this topological map",
    )
    s.add_argument(
        "--free-threshold",
        type=int,
        default=250,
        metavar="G",
        help="ground-truth grey value from which a pixel is free (default 250)",
    )
    s.add_argument(
        "--restrict",
        action="store_true",
        help="clip the segments to the ground truth's free pixels first (not done by the reference)",
    )
    s.add_argument("--json", action="store_true", help="print one JSON object (with per-room values)")
    s.set_defaults(handler=cmd_segment_score)


# ---------------------------------------------------------------------------- helpers


def load_map(path: Path, resolution: float | None, free_grey: int | None) -> Any:
    """The occupancy grid of ``path``: map_server rules, or ``grey >= free_grey`` is free."""
    import cv2

    from knowledge.errors import MapError
    from knowledge.metric.grid import OccupancyGrid

    if free_grey is None:
        return OccupancyGrid.load(path, resolution)
    if path.suffix.lower() in (".yaml", ".yml"):
        raise MapError(f"{path}: --free-grey applies to map images; a YAML map has its own thresholds")
    if not 0 <= free_grey <= 255:
        raise MapError(f"--free-grey must be a grey value 0..255, got {free_grey}")
    if resolution is None:
        raise MapError(
            f"{path}: an image map needs its resolution in metres per cell (e.g. --resolution 0.05)"
        )
    grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if grey is None:
        raise MapError(f"{path}: cannot read map image (missing file or unsupported format)")
    return OccupancyGrid.from_masks(grey < free_grey, resolution, name=path.stem)


def _thresholds(args: argparse.Namespace, model: Any) -> Any:
    """Correction thresholds from the options, completing them from the model (or the book)."""
    from knowledge.topology.pipeline import model_thresholds

    if args.place_min_area is None and args.doorway_min_area is None:
        return None
    base, _ = model_thresholds(model)
    d = base.to_dict()
    if args.place_min_area is not None:
        d["place_min_area_m2"] = args.place_min_area
    if args.doorway_min_area is not None:
        d["doorway_min_area_m2"] = args.doorway_min_area
    return type(base).from_dict(d)


# ---------------------------------------------------------------------------- topology


def cmd_topology(args: argparse.Namespace) -> int:
    import numpy as np

    from agent.progress import Progress
    from knowledge import labels as lbl
    from knowledge.fileio import atomic_write_text, write_image
    from knowledge.label_maps import label_map_yaml, legend_entries, with_legend, yaml_path
    from knowledge.places.model import PlaceModel, default_map_model_path
    from knowledge.topology.pipeline import TopologyConfig, build_topology
    from knowledge.topology.topomap import (
        draw_graph,
        draw_labels,
        draw_regions,
        dumps,
        map_background,
        overview,
        region_image,
    )

    if args.iterations < 0:
        raise SystemExit("loci places topology: --iterations must be >= 0")
    grid = load_map(args.map, args.resolution, args.free_grey)
    model_path = args.model or default_map_model_path()
    model = PlaceModel.load(model_path)
    config = TopologyConfig(
        iterations=args.iterations,
        correct=not args.no_correction,
        thresholds=_thresholds(args, model),
        grow_segments=not args.no_grow,
    )
    with Progress(enabled=not args.quiet) as progress:
        result = build_topology(grid, model, config, progress=progress, model_name=str(model_path))
    out: Path = args.out_dir
    out.mkdir(parents=True, exist_ok=True)
    paths = {k: out / v for k, v in OUTPUT_FILES.items()}
    legend = dict(result.class_names)
    lbl.write_label_image(paths["labels"], result.initial, legend)
    lbl.write_label_image(paths["relaxed"], result.relaxed, legend)
    lbl.write_label_image(paths["corrected"], result.corrected, legend)
    write_image(paths["regions"], region_image(result.graph))
    write_image(paths["segments"], result.segments.astype(np.uint16))
    for key in ("labels", "relaxed", "corrected", "regions", "segments"):
        ids = key in ("regions", "segments")
        text = label_map_yaml(
            paths[key].name, grid.resolution, grid.origin, legend=None if ids else legend, regions=ids
        )
        atomic_write_text(yaml_path(paths[key]), text)
    doc = result.document({"model": str(model_path), "map_file": str(args.map)})
    atomic_write_text(paths["graph"], dumps(doc))
    bg = map_background(grid)
    pic = overview(
        [
            ("labels before relaxation", draw_labels(bg, result.initial)),
            (f"after {args.iterations} relaxation iterations", draw_labels(bg, result.relaxed)),
            ("regions after the correction", draw_regions(result.graph, bg)),
            ("region graph", draw_graph(result.graph, bg)),
        ]
    )
    present = np.concatenate([result.initial.ravel(), result.relaxed.ravel(), result.corrected.ravel()])
    write_image(paths["overview"], with_legend(pic, legend_entries(present, legend)))

    free = grid.free
    n_free = int(free.sum())
    changed = int(np.sum((result.initial != result.relaxed) & free))
    changed_corr = int(np.sum((result.relaxed != result.corrected) & free))
    rounds = max((m.round for m in result.merges), default=0)
    seg_ids = np.unique(result.segments)
    summary: dict[str, Any] = {
        "map": str(args.map),
        "model": str(model_path),
        "rows": grid.shape[0],
        "cols": grid.shape[1],
        "resolution": grid.resolution,
        "free_cells": n_free,
        "classes": [result.class_names[c] for c in result.stats.classes],
        "iterations": args.iterations,
        "relaxation_changed_cells": changed,
        "correction": {
            "applied": result.thresholds is not None,
            "thresholds": None if result.thresholds is None else result.thresholds.to_dict(),
            "thresholds_source": result.thresholds_source,
            "merges": len(result.merges),
            "rounds": rounds,
            "changed_cells": changed_corr,
        },
        "regions": len(result.graph.regions),
        "regions_per_class": result.regions_per_class(),
        "edges": len(result.graph.edges),
        "segments": int(np.count_nonzero(seg_ids)),
        "timings_s": {k: round(float(v), 3) for k, v in result.timings.items()},
        "files": {k: str(p) for k, p in paths.items()},
    }
    if args.json:
        emit_json(summary)
        return 0
    print(
        f"topology of {grid.name}: {n_free} free cells ({grid.shape[0]} x {grid.shape[1]} at {grid.resolution} m), "
        f"model {model_path.name} ({', '.join(model.classes)})"
    )
    print(
        f"relaxation: {args.iterations} iterations changed {changed} cells ({100 * changed / max(n_free, 1):.1f} %)"
    )
    th = result.thresholds
    if th is None:
        print("correction: skipped")
    else:
        print(
            f"correction: {len(result.merges)} merges in {rounds} round{'' if rounds == 1 else 's'}, {changed_corr} cells changed "
            f"(thresholds from {result.thresholds_source}: places <= {th.place_min_area_m2:g} m², doorways <= "
            f"{th.doorway_min_area_m2:g} m² or with < {th.doorway_min_neighbours} neighbours)"
        )
    per_class = ", ".join(f"{c} {n}" for c, n in summary["regions_per_class"].items())
    print(f"regions: {len(result.graph.regions)} ({per_class}); edges: {len(result.graph.edges)}")
    print(
        f"segments: {summary['segments']} (room/corridor/hallway regions"
        + ("" if args.no_grow else ", other free cells grown into them")
        + ")"
    )
    t = result.timings
    print(
        "time: "
        + ", ".join(f"{k} {t[k]:.2f} s" for k in ("label", "relax", "correct", "regions", "segments"))
        + f"; total {t['total']:.1f} s"
    )
    print(f"wrote {', '.join(p.name for p in paths.values())} in {out}")
    return 0


# ---------------------------------------------------------------------------- segment-score


def _read_ids(path: Path) -> Any:
    import cv2

    from knowledge.errors import MapError

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise MapError(f"{path}: cannot read the image (missing file or not an image)")
    return img


def graph_segment_ids(doc: dict[str, Any], classes: tuple[str, ...] = _SEGMENT_CLASSES) -> list[int]:
    """Ids of the nodes of a topological map document whose label is one of ``classes``."""
    return sorted(int(n["id"]) for n in doc["nodes"] if n["label"] in classes)


def cmd_segment_score(args: argparse.Namespace) -> int:
    import numpy as np

    from knowledge.errors import MapError
    from knowledge.topology.segmentation_score import score, segment_ids
    from knowledge.topology.topomap import loads

    seg_img = _read_ids(args.segments)
    gt = _read_ids(args.gt)
    if gt.dtype != np.uint8:
        raise MapError(f"{args.gt}: a ground-truth segmentation must be an 8-bit picture, got {gt.dtype}")
    if seg_img.ndim == 3 and seg_img.dtype != np.uint8:
        raise MapError(f"{args.segments}: a colour segmentation must be 8-bit, got {seg_img.dtype}")
    if seg_img.shape[:2] != gt.shape[:2]:
        raise MapError(
            f"{args.segments} is {seg_img.shape[1]} x {seg_img.shape[0]} pixels but {args.gt} is "
            f"{gt.shape[1]} x {gt.shape[0]}: score a segmentation of the same map"
        )
    seg = segment_ids(seg_img)
    if args.graph is not None:
        try:
            doc = loads(args.graph.read_text())
        except OSError as exc:
            raise MapError(f"{args.graph}: cannot read the topological map ({exc.strerror})") from exc
        m = doc["map"]
        if (int(m["rows"]), int(m["cols"])) != seg.shape:
            raise MapError(
                f"{args.graph} describes a {m['rows']} x {m['cols']} map but {args.segments} is "
                f"{seg.shape[0]} x {seg.shape[1]}: pass the regions.png written with it"
            )
        keep = np.asarray(graph_segment_ids(doc), dtype=np.int64)
        seg = np.where(np.isin(seg, keep), seg, 0)
    result = score(seg, gt, free_threshold=args.free_threshold, restrict_to_gt_free=args.restrict)
    result = {"segments_file": str(args.segments), "gt_file": str(args.gt), **result}
    if args.json:
        emit_json(result)
        return 0
    print(
        f"{result['rooms']} rooms in {args.gt.name}, {result['segments']} segments of > 100 px in {args.segments.name}"
    )
    print(f"recall     mean {pct(result['recall_mean'])}   pooled {pct(result['recall_pooled'])}")
    print(f"precision  mean {pct(result['precision_mean'])}   pooled {pct(result['precision_pooled'])}")
    return 0
