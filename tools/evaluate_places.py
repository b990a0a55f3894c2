"""Leave-one-building-out evaluation of place classification on the real labelled maps.

For each of the five labelled IPA buildings: train on the other four (every STRIDE-th
labelled free cell), label EVERY free cell of the held-out one, and score the labels
(3-class room/corridor/doorway accuracy, 2-class room/corridor accuracy with doorway cells
ignored, balanced accuracy, confusion matrices). The bundled synthetic-trained model is
scored on the same five buildings. Writes ``places_lobo.json``, ``places_lobo.md`` and
one overlay picture per building into ``--out``.

Run: ``make eval`` (or ``python -m tools.evaluate_places --out docs/results``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from agent.datasets import data_dir
from agent.progress import Progress
from knowledge import labels as lbl
from knowledge.fileio import atomic_write_text, write_image
from knowledge.learning.metrics import Scores, score
from knowledge.places.dataset import IPA_BUILDINGS, LabelledMap, load_ipa_building
from knowledge.places.labeling import MapLabels, label_map
from knowledge.places.model import PlaceModel, default_model_path
from knowledge.places.training import HALLWAY_AS_CORRIDOR, TrainingConfig, train_place_model

CLASSES3 = ("room", "corridor", "doorway")
CLASSES2 = ("room", "corridor")


def score_labels(
    lmap: LabelledMap, result: MapLabels, merge: dict[str, str] | None = None
) -> dict[str, Scores]:
    """3-class and 2-class scores of a whole-map labeling against the map's labels."""
    cells = result.cells
    truth_codes = lmap.labels[cells[:, 0], cells[:, 1]]
    keep = truth_codes > 0
    truth = np.array([lmap.names[int(c)] for c in truth_codes[keep]])
    pred = result.predicted()[keep]
    if merge:
        pred = np.array([merge.get(c, c) for c in pred])
    return {"3": score(truth, pred, CLASSES3), "2": score(truth, pred, CLASSES2)}


def _row(name: str, s: dict[str, Scores], seconds: float) -> dict[str, Any]:
    return {
        "building": name,
        "cells": s["3"].n,
        "accuracy3": s["3"].accuracy,
        "balanced3": s["3"].balanced_accuracy,
        "accuracy2": s["2"].accuracy,
        "balanced2": s["2"].balanced_accuracy,
        "confusion3": s["3"].confusion.tolist(),
        "recall3": dict(
            zip(CLASSES3, [None if np.isnan(v) else float(v) for v in s["3"].recall], strict=True)
        ),
        "label_seconds": seconds,
    }


def _table(rows: list[dict[str, Any]]) -> list[str]:
    out = [
        "| building | cells | 3-class acc. | 3-class bal. | 2-class acc. | 2-class bal. | room / corridor / doorway recall |",
        "| --- | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    for r in rows:
        rec = " / ".join("–" if r["recall3"][c] is None else f"{100 * r['recall3'][c]:.1f}" for c in CLASSES3)
        out.append(
            f"| {r['building']} | {r['cells']:,} | {100 * r['accuracy3']:.2f} % | {100 * r['balanced3']:.2f} % | "
            f"{100 * r['accuracy2']:.2f} % | {100 * r['balanced2']:.2f} % | {rec} |"
        )
    mean = {
        k: float(np.mean([r[k] for r in rows])) for k in ("accuracy3", "balanced3", "accuracy2", "balanced2")
    }
    out.append(
        f"| **mean** | | **{100 * mean['accuracy3']:.2f} %** | {100 * mean['balanced3']:.2f} % | "
        f"**{100 * mean['accuracy2']:.2f} %** | {100 * mean['balanced2']:.2f} % | |"
    )
    return out


def _half_split(lmap: LabelledMap) -> tuple[LabelledMap, np.ndarray]:
    """The book's protocol (Sect. 3.6.1): train on the left half of a map, test on the right.

    Returns the map with labels only on the left half, and the free labelled cells of the right.
    """
    cols = np.argwhere(lmap.labelled_free())[:, 1]
    mid = int(np.median(cols))
    left = lmap.labels.copy()
    left[:, mid:] = 0
    right = np.argwhere(lmap.labelled_free())
    right = right[right[:, 1] >= mid]
    return LabelledMap(lmap.grid, left, lmap.names), right


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m tools.evaluate_places", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--data", type=Path, default=None, help="data folder (default $LOCI_DATA or ../shared/data)"
    )
    ap.add_argument(
        "--out", type=Path, default=Path("docs/results"), help="folder for the tables and pictures"
    )
    ap.add_argument("--stride", type=int, default=4, help="training stride in cells (default 4)")
    ap.add_argument("--rounds", type=int, default=100, help="boosting rounds T (default 100)")
    ap.add_argument("--only", action="append", default=[], help="evaluate only these held-out buildings")
    ap.add_argument("--quick", action="store_true", help="skip the variants (uniform weights, half splits)")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    data = args.data or data_dir()
    if not (data / "ipa" / "labeled").is_dir():
        print(f"no labelled maps under {data}/ipa/labeled: pass --data or set LOCI_DATA", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    maps = {b: load_ipa_building(data, b) for b in IPA_BUILDINGS}
    held_out = args.only or list(IPA_BUILDINGS)
    config = TrainingConfig(stride=args.stride, rounds=args.rounds, classes=CLASSES3)
    uniform = TrainingConfig(stride=args.stride, rounds=args.rounds, classes=CLASSES3, balanced=False)
    lobo: list[dict[str, Any]] = []
    lobo_uniform: list[dict[str, Any]] = []
    halves: list[dict[str, Any]] = []
    bundled: list[dict[str, Any]] = []
    default = PlaceModel.load(default_model_path())
    t_start = time.perf_counter()

    def say(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    with Progress(enabled=not args.quiet) as progress:
        for b in held_out:
            train = [m for name, m in maps.items() if name != b]
            say(f"[{b}] training on {', '.join(m.name for m in train)} ...")
            model, timings = train_place_model(train, config, progress=progress)
            result = label_map(maps[b].grid, model, progress=progress)
            row = _row(b, score_labels(maps[b], result), result.timings["total"])
            row.update(
                order=list(model.decision_list.order_),
                train_seconds=timings["total"],
                examples=model.data.examples_per_class,
            )
            lobo.append(row)
            write_image(args.out / f"lobo_{b}.png", lbl.overlay(maps[b].grid.to_image(), result.labels))
            say(f"[{b}] 3-class {100 * row['accuracy3']:.2f} %, 2-class {100 * row['accuracy2']:.2f} %")
            result_d = label_map(maps[b].grid, default, progress=progress)
            merge = dict(HALLWAY_AS_CORRIDOR)
            bundled.append(_row(b, score_labels(maps[b], result_d, merge), result_d.timings["total"]))
            if args.quick:
                continue
            model_u, _ = train_place_model(train, uniform, progress=progress)
            result_u = label_map(maps[b].grid, model_u, progress=progress)
            lobo_uniform.append(_row(b, score_labels(maps[b], result_u), result_u.timings["total"]))
            left, right = _half_split(maps[b])
            model_h, _ = train_place_model([left], config, progress=progress)
            result_h = label_map(maps[b].grid, model_h, cells=right, progress=progress)
            halves.append(_row(b, score_labels(maps[b], result_h), result_h.timings["total"]))
    cmd = "python -m tools.evaluate_places " + " ".join(argv if argv is not None else sys.argv[1:])
    doc = {
        "command": cmd.strip(),
        "config": config.as_json(),
        "leave_one_building_out": lobo,
        "leave_one_building_out_uniform_weights": lobo_uniform,
        "half_splits": halves,
        "bundled_model": bundled,
        "bundled_model_data": {"maps": len(default.data.maps), "examples": default.data.examples_per_class},
        "seconds": time.perf_counter() - t_start,
    }
    atomic_write_text(args.out / "places_lobo.json", json.dumps(doc, indent=2) + "\n")
    md = [
        "# Place classification on the real labelled maps",
        "",
        f"Made by `{doc['command']}` (`make eval`; see docs/places.md). Every free cell of the test "
        "part is labelled from its own simulated 360° scan (360 beams, 30 m); 3-class accuracy over "
        "room/corridor/doorway cells, 2-class over room/corridor cells (doorway cells ignored; a "
        "doorway prediction there counts as wrong).",
        "",
        f"## Leave one building out (train on four at stride {args.stride}, T = {args.rounds}; "
        "label every free cell of the fifth)",
        "",
        *_table(lobo),
        "",
        "Decision lists chosen: " + "; ".join(f"{r['building']}: {'-'.join(r['order'][:-1])}" for r in lobo),
        "",
    ]
    if lobo_uniform:
        md += [
            "## The same with uniform initial weights (`loci places train --uniform-weights`)",
            "",
            *_table(lobo_uniform),
            "",
        ]
    if halves:
        md += [
            "## Within one building, as in the book (train on the left half, label the right half)",
            "",
            *_table(halves),
            "",
        ]
    md += [
        "## The bundled model (trained on generated buildings only; hallway counted as corridor)",
        "",
        *_table(bundled),
        "",
    ]
    atomic_write_text(args.out / "places_lobo.md", "\n".join(md))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
