"""``loci demo``: the main job on embedded defaults, no hardware and no data needed.

For now it shows place classification end to end: it generates an office floor, labels
every free cell with the bundled place model, compares the labels with the floor's
ground truth and writes pictures a person can look at.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "demo",
        help="run the demo on embedded defaults (no hardware, no data needed)",
        description="Generate an office floor, label every free cell with the bundled place model, "
        "score the labels against the floor's ground truth and write pictures of the result.",
    )
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    p.add_argument("--seed", type=int, default=7, help="seed of the generated office floor (default 7)")
    p.add_argument("--model", type=Path, default=None, help="a place model (default: the bundled one)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.set_defaults(handler=cmd_demo)


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
    from knowledge.metric.buildings import generate_tour_office
    from knowledge.places.labeling import label_map
    from knowledge.places.metrics import format_confusion, score
    from knowledge.places.model import PlaceModel, default_model_path

    t0 = time.perf_counter()
    model = PlaceModel.load(args.model or default_model_path())
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
    lbl.write_label_image(args.out / "labels.png", result.labels, result.legend)
    write_image(args.out / "map.png", background)
    write_image(args.out / "labels.overlay.png", pred_img)
    write_image(
        args.out / "comparison.png",
        _side_by_side(
            truth_img, pred_img, ("ground truth", f"classified ({100 * s.accuracy:.1f} % correct)")
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
        f"pictures in {args.out}/: comparison.png (truth | classified), labels.overlay.png, labels.png, map.png"
    )
    return 0
