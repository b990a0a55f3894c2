"""``loci places``: train, evaluate and apply place classifiers on occupancy maps."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

from agent.commands.options import emit_json, pct
from agent.commands.topology import register_topology_commands
from agent.datasets import data_dir

log = logging.getLogger("loci.places")


# ---------------------------------------------------------------------------- arguments


def _add_map_sources(p: argparse.ArgumentParser, *, required_hint: str) -> None:
    g = p.add_argument_group("maps", f"labelled maps to use ({required_hint}); options can be combined")
    g.add_argument(
        "--map",
        action="append",
        default=[],
        metavar="MAP",
        help="an occupancy map: map_server YAML, or an image with --resolution (repeatable, pairs with --labels)",
    )
    g.add_argument(
        "--labels",
        action="append",
        default=[],
        metavar="LABELS",
        help="the label image of the preceding --map (8-bit PNG: 1 room, 2 corridor, 3 doorway, 4 hallway; "
        "or the IPA grey values 77/115/179)",
    )
    g.add_argument("--resolution", type=float, metavar="M", help="metres per cell for image maps (e.g. 0.05)")
    g.add_argument(
        "--codes",
        choices=("auto", "standard", "ipa"),
        default="auto",
        help="how label images encode classes (default: detect)",
    )
    g.add_argument(
        "--ipa",
        action="append",
        default=[],
        metavar="BUILDING",
        help="a labelled IPA building from DATA/ipa/labeled: Fr52, lab_d_furnitures, lab_intel, lab_ipa, office_e "
        "(repeatable; 'all' for the five)",
    )
    g.add_argument(
        "--generated",
        type=int,
        default=0,
        metavar="N",
        help="N procedurally generated office floors (seeds --seed, --seed+1, ...)",
    )
    g.add_argument("--seed", type=int, default=0, help="first seed of --generated buildings (default 0)")
    g.add_argument(
        "--data",
        type=Path,
        default=None,
        metavar="DIR",
        help="the data folder for --ipa (default: $LOCI_DATA or ../shared/data beside the repository)",
    )


def _load_maps(args: argparse.Namespace, progress: Any) -> list[Any]:
    from knowledge.places.dataset import IPA_BUILDINGS, LabelledMap, load_ipa_building, load_labelled_map
    from sim.buildings import generate_building

    maps: list[LabelledMap] = []
    if len(args.map) != len(args.labels):
        raise SystemExit(
            f"loci places: give one --labels per --map ({len(args.map)} maps, {len(args.labels)} label images)"
        )
    for m, lab in zip(args.map, args.labels, strict=True):
        maps.append(load_labelled_map(m, lab, resolution=args.resolution, codes=args.codes))
    names = list(IPA_BUILDINGS) if "all" in args.ipa else args.ipa
    data = args.data or data_dir()
    for b in names:
        if b not in IPA_BUILDINGS:
            raise SystemExit(
                f"loci places: unknown IPA building {b!r}; choose from {', '.join(IPA_BUILDINGS)}"
            )
        if not (data / "ipa" / "labeled").is_dir():
            raise SystemExit(f"loci places: {data}/ipa/labeled not found; pass --data DIR or set LOCI_DATA")
        maps.append(load_ipa_building(data, b))
    for i in range(args.generated):
        seed = args.seed + i
        b = generate_building(seed)
        maps.append(LabelledMap(b.grid, b.labels))
        progress("generating buildings", i + 1, args.generated)
    if not maps:
        raise SystemExit("loci places: no maps given: use --map/--labels, --ipa or --generated")
    return maps


def _parse_merge(values: list[str]) -> dict[str, str]:
    merge: dict[str, str] = {}
    for v in values:
        src, sep, dst = v.partition("=")
        if not sep or not src or not dst:
            raise SystemExit(f"loci places: --merge takes CLASS=CLASS (e.g. hallway=corridor), got {v!r}")
        merge[src.strip()] = dst.strip()
    return merge


def _csv(value: str | None) -> tuple[str, ...] | None:
    if not value:
        return None
    return tuple(v.strip() for v in value.split(",") if v.strip())


# ---------------------------------------------------------------------------- register


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "places",
        help="place classification from 2D laser scans (train, evaluate, label maps)",
        description="Semantic place labeling (book chapters 3-4): simulate a 360° scan in free cells of "
        "occupancy maps, boost simple geometric features into one-vs-all classifiers and arrange them "
        "in a probabilistic decision list.",
    )
    psub = p.add_subparsers(dest="places_command", metavar="COMMAND", required=True)

    t = psub.add_parser(
        "train",
        help="train a place model from labelled maps or generated buildings",
        description="Train a place model: scans from every STRIDE-th labelled free cell, all 309\n"
        "features, one generalized-AdaBoost booster per class, the decision-list order, and the\n"
        "label statistics for relaxation. Writes one .npz model file.",
        epilog="Example: loci places train --ipa Fr52 --ipa lab_ipa --stride 4 --out fr52_ipa.npz\n"
        "The bundled default model: loci places train --generated 40 --seed 1000 --stride 8 "
        "--out knowledge/places/models/default.npz",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_map_sources(t, required_hint="at least one")
    t.add_argument("--out", type=Path, required=True, metavar="MODEL.npz", help="where to write the model")
    t.add_argument("--stride", type=int, default=4, help="take a scan every STRIDE cells (default 4)")
    t.add_argument("--classes", metavar="A,B,...", help="classes to learn (default: every class in the maps)")
    t.add_argument(
        "--merge",
        action="append",
        default=[],
        metavar="FROM=TO",
        help="rename a class before training, e.g. hallway=corridor (repeatable)",
    )
    t.add_argument(
        "--rounds", type=int, default=100, metavar="T", help="boosting rounds per classifier (100)"
    )
    t.add_argument(
        "--order",
        default="best",
        metavar="ORDER",
        help="decision-list order: best (try all), heuristic (by training error) or A,B,C (default best)",
    )
    t.add_argument("--booster", choices=("generalized", "discrete"), default="generalized")
    t.add_argument(
        "--uniform-weights",
        action="store_true",
        help="start boosting from uniform example weights instead of the book's class-balanced ones",
    )
    t.add_argument("--beams", type=int, default=360, help="beams of the simulated 360° scans (360)")
    t.add_argument("--max-range", type=float, default=30.0, metavar="M", help="sensor maximum range (30 m)")
    t.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    t.set_defaults(handler=cmd_train)

    e = psub.add_parser(
        "evaluate",
        help="accuracy, confusion matrix and the table of all decision-list orders on labelled maps",
        description="Classify scans simulated in the labelled free cells of maps and compare with the labels: "
        "accuracy, balanced accuracy, 2-class (room/corridor, doorway cells ignored) accuracy, the "
        "confusion matrix, and every decision-list order's accuracy (the book's Tables 3.1-3.3).",
    )
    _add_map_sources(e, required_hint="at least one")
    e.add_argument(
        "--model",
        type=Path,
        default=None,
        help="a place model (default: the bundled map model, default_map.npz)",
    )
    e.add_argument("--stride", type=int, default=1, help="evaluate every STRIDE-th cell (default 1: all)")
    e.add_argument(
        "--merge",
        action="append",
        default=[],
        metavar="FROM=TO",
        help="rename classes in truth and predictions, e.g. hallway=corridor for the IPA maps",
    )
    e.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    e.set_defaults(handler=cmd_evaluate)

    la = psub.add_parser(
        "label",
        help="label every free cell of a map",
        description="Label every free cell of an occupancy map with a place model. Writes the label codes "
        "(0 none, 1 room, 2 corridor, 3 doorway, 4 hallway) as an 8-bit PNG and a coloured overlay PNG.",
        epilog="--method iamn (Sect. 4.6) labels all cells together: nodes every 0.2 m, FDR-selected features, "
        "nearest-neighbour transform, MAP in an associative Markov network; it needs an iAMN --model "
        "(tools/iamn_experiment.py writes one; docs/places.md, 'iAMN (Sect. 4.6)').",
    )
    la.add_argument("map", type=Path, metavar="MAP", help="map_server YAML, or an image with --resolution")
    la.add_argument("--resolution", type=float, metavar="M", help="metres per cell for image maps")
    la.add_argument(
        "--model",
        type=Path,
        default=None,
        help="a place model (default: the bundled map model, default_map.npz; --method iamn: required)",
    )
    la.add_argument(
        "--method",
        choices=("adaboost", "iamn"),
        default="adaboost",
        help="adaboost: the decision list cell by cell (default); iamn: an instance-based associative Markov network",
    )
    la.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="LABELS.png",
        help="the label image to write (a file); LABELS.yaml, its map_server description, is written beside it",
    )
    la.add_argument(
        "--overlay",
        type=Path,
        default=None,
        metavar="PNG",
        help="coloured picture with a legend to write (a file; default: LABELS.overlay.png beside --out)",
    )
    la.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    la.set_defaults(handler=cmd_label)

    d = psub.add_parser(
        "demo",
        help="label every free cell of a generated office and compare with its ground truth",
        description="Generate an office floor, label every free cell with the bundled place model, "
        "score the labels against the floor's ground truth and write pictures of the result.",
    )
    d.add_argument(
        "--out-dir",
        "--out",
        dest="out",
        type=Path,
        default=Path("out/places-demo"),
        metavar="DIR",
        help="the folder to write into (default out/places-demo; --out is the old name)",
    )
    d.add_argument("--seed", type=int, default=7, help="seed of the generated office floor (default 7)")
    d.add_argument(
        "--model",
        type=Path,
        default=None,
        help="a place model (default: the bundled map model, default_map.npz)",
    )
    d.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    d.set_defaults(handler=cmd_demo)

    td = psub.add_parser(
        "train-default",
        help="train the bundled models (the agent's and the map model) on all the labelled data",
        description="Train the two bundled place models, reproducibly (fixed seeds), on the five labelled IPA "
        "buildings, generated office floors and the real labelled Freiburg 079 scans, with domain "
        "randomisation and simulated drives (docs/places.md, 'The bundled models'): default.npz for the "
        "agent (loci run, loci replay; with the trajectory HMM) and default_map.npz for whole-map "
        "labeling (loci places label, loci places topology). About 20 minutes on one core.",
        epilog="Example: loci places train-default --cache /tmp/loci-places-cache\n"
        "Leave a building out (to evaluate on it): --without fr079 --out-dir /tmp/models",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    td.add_argument(
        "--data",
        type=Path,
        default=None,
        metavar="DIR",
        help="the data folder (default: $LOCI_DATA or ../shared/data beside the repository)",
    )
    td.add_argument(
        "--out-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="where to write default.npz and default_map.npz (default: the bundled models' folder)",
    )
    td.add_argument(
        "--without",
        action="append",
        default=[],
        metavar="BUILDING",
        help="leave a building out: fr079 or an IPA building (repeatable)",
    )
    td.add_argument(
        "--generated", type=int, default=None, metavar="N", help="generated buildings (default 10)"
    )
    td.add_argument(
        "--only",
        choices=("agent", "map"),
        default=None,
        help="train only the agent's model or only the map model",
    )
    td.add_argument(
        "--cache",
        type=Path,
        default=None,
        metavar="DIR",
        help="keep the simulated training scans here and reuse them (e.g. /tmp/loci-places-cache)",
    )
    td.add_argument(
        "--rounds",
        type=int,
        default=None,
        metavar="T",
        help="boosting rounds (default 100; fewer only to test)",
    )
    td.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    td.set_defaults(handler=cmd_train_default)

    register_topology_commands(psub)


# ---------------------------------------------------------------------------- handlers


def _load_model(path: Path | None) -> Any:
    from knowledge.places.model import PlaceModel, default_map_model_path

    return PlaceModel.load(path or default_map_model_path())


def cmd_train(args: argparse.Namespace) -> int:
    from agent.progress import Progress
    from knowledge.places.training import TrainingConfig, train_place_model

    order: str | tuple[str, ...] = args.order
    if args.order not in ("best", "heuristic"):
        order = _csv(args.order) or ()
    config = TrainingConfig(
        classes=_csv(args.classes),
        merge=_parse_merge(args.merge),
        stride=args.stride,
        n_beams=args.beams,
        max_range=args.max_range,
        rounds=args.rounds,
        booster=args.booster,
        order=order,
        balanced=not args.uniform_weights,
    )
    with Progress(enabled=not args.quiet) as progress:
        maps = _load_maps(args, progress)
        _check_classes(maps, config)
        log.info("training on %d maps: %s", len(maps), ", ".join(m.name for m in maps))
        model, timings = train_place_model(maps, config, progress=progress)
    model.save(args.out)
    dl = model.decision_list
    summary = {
        "model": str(args.out),
        "maps": list(model.data.maps),
        "examples_per_class": model.data.examples_per_class,
        "classes": list(model.classes),
        "order": list(dl.order_),
        "order_scores": [{"order": list(o), "accuracy": a} for o, a in dl.order_scores_],
        "train_errors": dl.train_errors_,
        "features_used": len(model.feature_names),
        "features_for_prediction": len(model.prediction_columns()),
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }
    if args.json:
        emit_json(summary)
        return 0
    print(f"trained on {len(maps)} maps ({', '.join(model.data.maps)})")
    print("examples: " + ", ".join(f"{c} {n}" for c, n in model.data.examples_per_class.items()))
    print(
        f"decision list: {' -> '.join(dl.order_)}  ({dl.selection_} accuracy {pct(dl.order_scores_[0][1])})"
    )
    print(
        f"features: {len(model.prediction_columns())} computed for prediction "
        f"({len(model.feature_names)} kept for scoring other orders)"
    )
    print(
        "time: "
        + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items() if k != "total")
        + f"; total {timings['total']:.1f} s"
    )
    print(f"wrote {args.out}")
    return 0


def cmd_train_default(args: argparse.Namespace) -> int:
    from agent.progress import Progress
    from agent.training.default_models import GENERATED, train_default
    from knowledge.places.model import default_model_path

    data = args.data or data_dir()
    if not (data / "ipa" / "labeled").is_dir():
        raise SystemExit(
            f"loci places train-default: {data}/ipa/labeled not found; pass --data DIR or set LOCI_DATA"
        )
    out_dir = args.out_dir or default_model_path().parent
    which = (args.only,) if args.only else ("agent", "map")
    with Progress(enabled=not args.quiet) as progress:
        summary = train_default(
            data,
            out_dir,
            without=args.without,
            generated=GENERATED if args.generated is None else args.generated,
            cache=args.cache,
            which=which,
            rounds=args.rounds,
            progress=progress,
        )
    if args.json:
        emit_json(summary)
        return 0
    print(f"trained on {len(summary['maps'])} buildings: {', '.join(summary['maps'])}")
    print("examples: " + ", ".join(f"{k} {n:,}" for k, n in summary["examples_per_kind"].items()))
    for kind, path in summary["files"].items():
        print(f"wrote the {kind} model {path}")
    print(f"took {summary['seconds']['total']:.0f} s")
    return 0


def _check_classes(maps: list[Any], config: Any) -> None:
    """Refuse --classes/--order that do not fit the maps before any scan is cast."""
    from knowledge.places.training import merge_classes

    present: set[str] = set()
    for m in maps:
        present |= set(merge_classes(m, config.merge).class_counts())
    classes = set(config.classes) if config.classes else present
    missing = sorted(classes - present)
    if missing:
        raise ValueError(f"--classes names {missing}, which no map labels; the maps have {sorted(present)}")
    if not isinstance(config.order, str) and set(config.order) != classes:
        raise ValueError(f"--order must list every class once: {sorted(classes)} (got {list(config.order)})")


def _importance_table(model: Any, top: int = 7) -> dict[str, list[str]]:
    """The book's Table 3.5: the most important features of each binary classifier."""
    out: dict[str, list[str]] = {}
    for cls, booster in model.decision_list.boosters_.items():
        imp = booster.feature_importance()
        order = sorted(range(len(imp)), key=lambda i: -imp[i])[:top]
        out[cls] = [model.feature_names[i] for i in order if imp[i] > 0]
    return out


def cmd_evaluate(args: argparse.Namespace) -> int:
    import numpy as np

    from agent.progress import Progress
    from knowledge.learning.decision_list import order_name
    from knowledge.learning.metrics import format_confusion, score
    from knowledge.places.dataset import simulate_scans
    from knowledge.places.training import merge_classes

    model = _load_model(args.model)
    merge = _parse_merge(args.merge)
    with Progress(enabled=not args.quiet) as progress:
        maps = [merge_classes(m, merge) for m in _load_maps(args, progress)]
        t0 = time.perf_counter()
        scans = simulate_scans(
            maps,
            stride=args.stride,
            n_beams=model.scan.n_beams,
            max_range=model.scan.max_range,
            progress=progress,
        )
        t1 = time.perf_counter()
        X = np.empty((len(scans), len(model.feature_names)), dtype=np.float32)
        for start in range(0, len(scans), 16384):
            stop = min(len(scans), start + 16384)
            X[start:stop] = model.features(scans.ranges[start:stop], all_features=True)
            progress("features", stop, len(scans))
    t2 = time.perf_counter()
    classes = [c for c in model.classes if c not in merge]
    known = np.isin(scans.y, classes)
    ignored = {str(c): int(n) for c, n in zip(*np.unique(scans.y[~known], return_counts=True), strict=True)}
    X, truth = X[known], scans.y[known]
    pred = model.decision_list.predict(X)
    pred = np.array([merge.get(c, c) for c in pred]) if merge else pred
    t3 = time.perf_counter()
    s_all = score(truth, pred, classes)
    two = [c for c in ("room", "corridor") if c in classes]
    s_two = score(truth, pred, two) if len(two) == 2 else None
    orders = []
    if not merge and all(c in model.decision_list.boosters_ for c in model.classes):
        orders = model.decision_list.order_accuracies(X, truth)
    result: dict[str, Any] = {
        "model": str(args.model or "bundled default"),
        "maps": list(scans.maps),
        "examples": int(known.sum()),
        "ignored": ignored,
        "classes": classes,
        "order": list(model.decision_list.order_),
        **{k: v for k, v in s_all.as_dict().items() if k != "n"},
        "two_class_accuracy": None if s_two is None else round(s_two.accuracy, 6),
        "two_class_balanced_accuracy": None if s_two is None else round(s_two.balanced_accuracy, 6),
        "orders": [{"order": list(o), "name": order_name(o), "accuracy": round(a, 6)} for o, a in orders],
        "important_features": _importance_table(model),
        "timings_s": {
            "scans": round(t1 - t0, 3),
            "features": round(t2 - t1, 3),
            "classify": round(t3 - t2, 3),
        },
    }
    if args.json:
        emit_json(result)
        return 0
    print(
        f"{int(known.sum())} scans in {', '.join(scans.maps)}; "
        f"model order {' -> '.join(model.decision_list.order_)}"
    )
    if ignored:
        hint = "; count halls as corridors with --merge hallway=corridor" if "hallway" in ignored else ""
        print(
            "not scored (classes the model does not have): "
            + ", ".join(f"{c} {n}" for c, n in ignored.items())
            + (hint or "; rename them with --merge CLASS=CLASS")
        )
    print(f"accuracy            {pct(s_all.accuracy)}   ({len(classes)} classes)")
    print(f"balanced accuracy   {pct(s_all.balanced_accuracy)}")
    if s_two is not None:
        print(f"room/corridor       {pct(s_two.accuracy)}   (doorway cells ignored)")
    print()
    print(format_confusion(s_all))
    if orders:
        print()
        print("decision list        accuracy")
        for o, a in orders:
            mark = "  <- model" if tuple(o) == tuple(model.decision_list.order_) else ""
            print(f"{order_name(o):<20} {pct(a)}{mark}")
    print()
    print("most important features (book Table 3.5):")
    for cls, names in result["important_features"].items():
        print(f"  {cls:<10} {', '.join(names)}")
    return 0


def cmd_label(args: argparse.Namespace) -> int:
    import numpy as np

    from agent.progress import Progress
    from knowledge import labels as lbl
    from knowledge.errors import MapError
    from knowledge.fileio import write_image
    from knowledge.label_maps import legend_entries, with_legend, write_label_map, yaml_path
    from knowledge.metric.grid import OccupancyGrid
    from knowledge.places.labeling import label_map

    described = yaml_path(args.out)
    if described.resolve() == Path(args.map).resolve():
        raise MapError(
            f"--out {args.out} would replace the input map {args.map} with its YAML; name it otherwise"
        )
    grid = OccupancyGrid.load(args.map, args.resolution)
    if args.method == "iamn":
        from knowledge.places.iamn import IAMNModel, label_map_iamn

        if args.model is None:
            raise SystemExit(
                "loci places label: --method iamn needs --model IAMN.npz (there is no bundled iAMN)"
            )
        iamn = IAMNModel.load(args.model)
        with Progress(enabled=not args.quiet) as progress:
            result, _, _ = label_map_iamn(grid, iamn, progress=progress)
    else:
        if not grid.free.any():
            raise MapError(f"{args.map}: no free cells to label; is the map's free space white?")
        model = _load_model(args.model)
        with Progress(enabled=not args.quiet) as progress:
            result = label_map(grid, model, progress=progress)
    write_label_map(args.out, result.labels, grid.resolution, grid.origin, result.legend)
    overlay_path = args.overlay or args.out.with_name(args.out.stem + ".overlay.png")
    picture = lbl.overlay(grid.to_image(), result.labels)
    write_image(overlay_path, with_legend(picture, legend_entries(result.labels, result.legend)))
    counts = {c: int(np.sum(result.labels == code)) for c, code in result.codes.items()}
    area = {c: round(n * grid.resolution**2, 2) for c, n in counts.items()}
    summary = {
        "map": str(args.map),
        "method": args.method,
        "cells": len(result.cells),
        "resolution": grid.resolution,
        "classes": list(result.classes),
        "cells_per_class": counts,
        "area_m2_per_class": area,
        "labels": str(args.out),
        "labels_yaml": str(described),
        "overlay": str(overlay_path),
        "timings_s": {k: round(v, 3) for k, v in result.timings.items()},
    }
    if args.json:
        emit_json(summary)
        return 0
    print(f"labelled {len(result.cells)} free cells of {grid.name} in {result.timings['total']:.1f} s")
    for c in result.classes:
        print(f"  {c:<10} {counts[c]:>9} cells  {area[c]:>9.1f} m²")
    print(f"wrote {args.out}, {described} (map_server, mode raw) and {overlay_path}")
    return 0


# ---------------------------------------------------------------------------- loci places demo
def _side_by_side(left: Any, right: Any, titles: tuple[str, str]) -> Any:
    import cv2
    import numpy as np

    h = max(left.shape[0], right.shape[0])
    pad = 12
    band = 36
    canvas = np.full((h + band, left.shape[1] + right.shape[1] + pad, 3), 255, np.uint8)
    canvas[band : band + left.shape[0], : left.shape[1]] = left
    canvas[band : band + right.shape[0], left.shape[1] + pad :] = right
    for x, text in ((8, titles[0]), (left.shape[1] + pad + 8, titles[1])):
        cv2.putText(canvas, text, (x, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (30, 30, 30), 2, cv2.LINE_AA)
    return canvas


def cmd_demo(args: argparse.Namespace) -> int:
    import numpy as np

    from agent.progress import Progress
    from knowledge import labels as lbl
    from knowledge.fileio import write_image
    from knowledge.label_maps import legend_entries, with_legend, write_label_map
    from knowledge.learning.metrics import format_confusion, score
    from knowledge.places.labeling import label_map
    from knowledge.places.model import PlaceModel, default_map_model_path
    from sim.buildings import generate_tour_office

    t0 = time.perf_counter()
    model = PlaceModel.load(args.model or default_map_model_path())
    building = generate_tour_office(args.seed)
    grid = building.grid
    if not args.json:
        w, h = grid.size_m
        print(
            f"generated office floor (seed {args.seed}): {w:.0f} m × {h:.0f} m, {int(grid.free.sum())} free cells"
        )
        print(f"labeling every free cell with {args.model or 'the bundled model'} ...", flush=True)
    with Progress(enabled=not args.quiet) as progress:
        result = label_map(grid, model, progress=progress)
    # the truth, in the model's classes (a model without hallways calls them corridors)
    truth_codes = building.labels[result.cells[:, 0], result.cells[:, 1]]
    truth = np.array([lbl.CLASS_NAMES.get(int(c), "none") for c in truth_codes])
    if "hallway" not in model.classes:
        truth[truth == "hallway"] = "corridor"
    s = score(truth, result.predicted(), model.classes)

    args.out.mkdir(parents=True, exist_ok=True)
    background = grid.to_image()
    truth_img = lbl.overlay(background, building.labels)
    pred_img = lbl.overlay(background, result.labels)
    write_label_map(args.out / "labels.png", result.labels, grid.resolution, grid.origin, result.legend)
    grid.save(args.out / "map.yaml")  # map.pgm + map.yaml: the occupancy map for map_server
    write_image(args.out / "map.png", background)
    entries = legend_entries(np.concatenate([building.labels.ravel(), result.labels.ravel()]), result.legend)
    write_image(args.out / "labels.overlay.png", with_legend(pred_img, entries))
    write_image(
        args.out / "comparison.png",
        with_legend(
            _side_by_side(
                truth_img, pred_img, ("ground truth", f"classified ({100 * s.accuracy:.1f} % correct)")
            ),
            entries,
        ),
    )
    summary = {
        "seed": args.seed,
        "cells": len(result.cells),
        "classes": list(model.classes),
        "accuracy": s.accuracy,
        "balanced_accuracy": s.balanced_accuracy,
        "confusion": s.confusion.tolist(),
        "timings_s": {k: round(v, 3) for k, v in result.timings.items()},
        "outputs": sorted(str(p) for p in args.out.iterdir()),
        "seconds": round(time.perf_counter() - t0, 3),
    }
    if args.json:
        json.dump(summary, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    print(
        f"\naccuracy {100 * s.accuracy:.2f} % (balanced {100 * s.balanced_accuracy:.2f} %) on {s.n} cells\n"
    )
    print(format_confusion(s))
    print(
        f"\nlabeling took {result.timings['total']:.1f} s "
        f"(ray casting {result.timings['cast']:.1f} s, features and classification {result.timings['classify']:.1f} s)"
    )
    print(
        f"pictures in {args.out}/: comparison.png (truth | classified), labels.overlay.png, labels.png "
        "with labels.yaml, map.png, map.pgm with map.yaml"
    )
    return 0
